#include "mild_lcd/io/database_directory.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string_view>
#include <utility>
#include <vector>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

namespace fs = std::filesystem;

constexpr size_t kMaxPathBytes = 4096;
constexpr size_t kMaxComponentBytes = 255;

std::string errnoText(int error) { return std::strerror(error); }

// Temporary files of saves to `target`: ".<target>.mild-lcd-save.<16 hex digits>": hidden, tagged
// with the node's name and 64 random bits, a name no user chooses and one a save refuses as a map's
// (DatabaseDirectory::resolve), so that only a save makes one.
constexpr char kTemporaryTag[] = ".mild-lcd-save.";
constexpr size_t kTemporaryTagBytes = sizeof(kTemporaryTag) - 1;
constexpr size_t kTemporaryDigits = 16;
constexpr size_t kMaxTemporaryExtraBytes = 1 + kTemporaryTagBytes + kTemporaryDigits;  // what a temporary adds
std::string temporaryPrefix(const std::string& target) { return "." + target + kTemporaryTag; }

std::string randomSuffix() {
  static std::atomic<uint64_t> counter{0};
  uint64_t x = static_cast<uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count()) ^
               (static_cast<uint64_t>(::getpid()) << 32) ^ (counter.fetch_add(1) * 0x9E3779B97F4A7C15ull);
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdull;
  x ^= x >> 33;
  char text[17];
  std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(x));
  return std::string(text, kTemporaryDigits);
}

// Whether the file starts with `signature`, or with its beginning when shorter (a save killed
// before it wrote more: an empty file included).
bool startsWithSignature(int fd, off_t size, std::string_view signature) {
  const size_t wanted = std::min(signature.size(), static_cast<size_t>(size));
  std::string head(wanted, '\0');
  size_t done = 0;
  while (done < wanted) {
    const ssize_t n = ::pread(fd, head.data() + done, wanted - done, static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += static_cast<size_t>(n);
  }
  return head == signature.substr(0, wanted);
}

// Removes temporary files that killed saves left behind, and nothing else. A file is one only when
// every test holds: its name is a temporary's of this target (temporaryPrefix + 16 hex digits); it
// is a regular file with one name, owned by this process's user; it starts with `signature` (the
// format's magic, which replace writes first) or is a beginning of it; it is over a minute old
// (covering the instant between a save creating its file and locking it); and its lock can be
// taken (a save in progress holds it). It is unlinked while that lock is held.
void removeStaleTemporaries(const ConfinedFile& file, std::string_view signature) {
  const int dup_fd = ::dup(file.folder());
  if (dup_fd < 0) return;
  DIR* dir = ::fdopendir(dup_fd);
  if (dir == nullptr) {
    ::close(dup_fd);
    return;
  }
  const std::string prefix = temporaryPrefix(file.name());
  const auto now = std::chrono::system_clock::now();
  std::vector<std::pair<std::string, int>> stale;  // name, its locked descriptor
  while (const dirent* entry = ::readdir(dir)) {
    const std::string name = entry->d_name;
    if (name.size() != prefix.size() + kTemporaryDigits || name.compare(0, prefix.size(), prefix) != 0 ||
        !isTemporaryFileName(name)) {
      continue;
    }
    const int fd = ::openat(file.folder(), name.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) continue;  // a link or a vanished file: not ours to remove
    struct stat st {};
    const bool ours = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_nlink == 1 && st.st_uid == ::geteuid() &&
                      now - std::chrono::system_clock::from_time_t(st.st_mtime) > std::chrono::seconds(60) &&
                      startsWithSignature(fd, st.st_size, signature) && ::flock(fd, LOCK_EX | LOCK_NB) == 0;
    if (ours) {
      stale.emplace_back(name, fd);
    } else {
      ::close(fd);
    }
  }
  ::closedir(dir);
  for (const auto& [name, fd] : stale) {
    ::unlinkat(file.folder(), name.c_str(), 0);
    ::close(fd);
  }
}

// A new temporary file beside the target, created exclusively (never an existing file or a link)
// and locked for the duration of the save.
int createTemporary(const ConfinedFile& file, std::string& name) {
  for (int attempt = 0; attempt < 16; ++attempt) {
    name = temporaryPrefix(file.name()) + randomSuffix();
    const int fd = ::openat(file.folder(), name.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
    if (fd >= 0) {
      ::flock(fd, LOCK_EX);
      return fd;
    }
    if (errno != EEXIST) break;
  }
  throw IoError(file.display() + ": cannot create a temporary file beside it (" + errnoText(errno) + ")");
}

const char* kindOf(mode_t mode) {
  if (S_ISDIR(mode)) return "a folder";
  if (S_ISLNK(mode)) return "a symbolic link";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISSOCK(mode)) return "a socket";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  return "not a regular file";
}

std::vector<std::string> components(const std::string& relative, const std::string& requested) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= relative.size()) {
    const size_t slash = relative.find('/', start);
    const std::string part = relative.substr(start, slash == std::string::npos ? std::string::npos : slash - start);
    if (part.empty() || part == ".") {
      throw InvalidInput("database name '" + requested + "' has an empty or '.' component");
    }
    if (part == "..") throw InvalidInput("database name '" + requested + "' must not contain '..'");
    if (part.size() > kMaxComponentBytes) {
      throw InvalidInput("database name '" + requested + "' has a component longer than 255 bytes");
    }
    out.push_back(part);
    if (slash == std::string::npos) break;
    start = slash + 1;
  }
  return out;
}

}  // namespace

bool isTemporaryFileName(const std::string& name) {
  const size_t tail = kTemporaryTagBytes + kTemporaryDigits;
  if (name.size() < tail + 2 || name.front() != '.') return false;
  if (name.compare(name.size() - tail, kTemporaryTagBytes, kTemporaryTag) != 0) return false;
  return std::all_of(name.end() - static_cast<long>(kTemporaryDigits), name.end(),
                     [](char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); });
}

bool isTeamLedgerName(const std::string& name) {
  const auto ends_with = [&name](const std::string& tail) {
    return name.size() >= tail.size() && name.compare(name.size() - tail.size(), tail.size(), tail) == 0;
  };
  return ends_with(kTeamLedgerSuffix) || ends_with(std::string(kTeamLedgerSuffix) + kTeamLedgerTemporarySuffix);
}

ConfinedFile::ConfinedFile(int folder_fd, std::string name, std::string display)
    : folder_fd_(folder_fd), name_(std::move(name)), display_(std::move(display)) {}

ConfinedFile::ConfinedFile(ConfinedFile&& other) noexcept
    : folder_fd_(other.folder_fd_), name_(std::move(other.name_)), display_(std::move(other.display_)) {
  other.folder_fd_ = -1;
}

ConfinedFile& ConfinedFile::operator=(ConfinedFile&& other) noexcept {
  if (this != &other) {
    if (folder_fd_ >= 0) ::close(folder_fd_);
    folder_fd_ = other.folder_fd_;
    name_ = std::move(other.name_);
    display_ = std::move(other.display_);
    other.folder_fd_ = -1;
  }
  return *this;
}

ConfinedFile::~ConfinedFile() {
  if (folder_fd_ >= 0) ::close(folder_fd_);
}

bool ConfinedFile::exists() const {
  struct stat st {};
  return ::fstatat(folder_fd_, name_.c_str(), &st, AT_SYMLINK_NOFOLLOW) == 0;
}

void ConfinedFile::refuseIfNotRegular() const {
  struct stat st {};
  if (::fstatat(folder_fd_, name_.c_str(), &st, AT_SYMLINK_NOFOLLOW) != 0) return;  // absent: fine
  if (!S_ISREG(st.st_mode)) {
    throw InvalidInput(display_ + " is " + kindOf(st.st_mode) + ", not a regular file: refusing to replace it");
  }
}

void ConfinedFile::replace(const std::function<void(int fd)>& write, std::string_view signature) const {
  refuseIfNotRegular();
  removeStaleTemporaries(*this, signature);
  std::string tmp;
  const int fd = createTemporary(*this, tmp);
  try {
    // The mark of a save's own temporary file (removeStaleTemporaries checks it), from the start.
    size_t done = 0;
    while (done < signature.size()) {
      const ssize_t n = ::pwrite(fd, signature.data() + done, signature.size() - done, static_cast<off_t>(done));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw IoError(display_ + ": cannot write a temporary file beside it (" + errnoText(errno) + ")");
      done += static_cast<size_t>(n);
    }
    write(fd);
    if (::fsync(fd) != 0) throw IoError(display_ + ": cannot flush to disk (" + errnoText(errno) + ")");
  } catch (...) {
    ::unlinkat(folder_fd_, tmp.c_str(), 0);
    ::close(fd);
    throw;
  }
  // Renamed while still locked: the temporary file is never unlocked under its temporary name.
  if (::renameat(folder_fd_, tmp.c_str(), folder_fd_, name_.c_str()) != 0) {
    const std::string why = errnoText(errno);
    ::unlinkat(folder_fd_, tmp.c_str(), 0);
    ::close(fd);
    throw IoError(display_ + ": cannot replace the file (" + why + ")");
  }
  ::close(fd);
  ::fsync(folder_fd_);  // the rename itself must reach the disk too
}

void ConfinedFile::replaceText(const std::string& text, std::string_view signature) const {
  replace(
      [&text, this](int fd) {
        size_t done = 0;
        while (done < text.size()) {
          const ssize_t n = ::pwrite(fd, text.data() + done, text.size() - done, static_cast<off_t>(done));
          if (n < 0 && errno == EINTR) continue;
          if (n <= 0) throw IoError("cannot write " + display_ + ": " + std::string(std::strerror(errno)));
          done += static_cast<size_t>(n);
        }
      },
      signature);
}

std::string ConfinedFile::readText() const {
  unsigned long long size = 0;
  const int fd = openForReading(size);
  std::string text(size, '\0');
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::read(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    done += static_cast<size_t>(n);
  }
  ::close(fd);
  if (done != text.size()) throw IoError("cannot read " + display_ + " whole");
  return text;
}

int ConfinedFile::openForReading(unsigned long long& size) const {
  // O_NONBLOCK: opening a FIFO must not wait for a writer; O_NOFOLLOW: a link is refused (ELOOP).
  const int fd = ::openat(folder_fd_, name_.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    const int error = errno;
    if (error == ELOOP) throw InvalidInput(display_ + " is a symbolic link: database files must be regular files");
    throw IoError(display_ + ": cannot open (" + errnoText(error) + ")");
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    const mode_t mode = st.st_mode;
    ::close(fd);
    throw InvalidInput(display_ + " is " + kindOf(mode) + ": database files must be regular files");
  }
  // A hard link is a second name of a file that may live anywhere on the file system: one planted
  // in the folder (by anyone who may write there) would let a client read a file outside it.
  if (st.st_nlink > 1) {
    ::close(fd);
    throw InvalidInput(display_ + " has " + std::to_string(st.st_nlink) +
                       " hard links: database files must have one name, in the database folder");
  }
  // Regular files never block; reading with O_NONBLOCK cleared keeps read() semantics plain.
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  size = static_cast<unsigned long long>(st.st_size);
  return fd;
}

ConfinedFile fileAtPath(const std::string& path) {
  if (path.empty()) throw InvalidInput("empty database path");
  const fs::path p(path);
  const std::string folder = p.has_parent_path() ? p.parent_path().string() : ".";
  const std::string name = p.filename().string();
  if (name.empty() || name == "." || name == "..") throw InvalidInput(path + ": not a file name");
  const int fd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) throw IoError(path + ": cannot open its folder " + folder + " (" + errnoText(errno) + ")");
  return ConfinedFile(fd, name, path);
}

DatabaseDirectory::DatabaseDirectory(const std::string& root, const DirectoryLimits& limits) : limits_(limits) {
  if (root.empty() || root.front() != '/') {
    throw InvalidInput("database folder must be an absolute path, got '" + root + "'");
  }
  std::error_code error;
  fs::create_directories(root, error);
  if (!fs::is_directory(root)) {
    throw IoError("database folder " + root + " cannot be created" + (error ? " (" + error.message() + ")" : ""));
  }
  root_ = fs::path(root).lexically_normal().string();
  while (root_.size() > 1 && root_.back() == '/') root_.pop_back();
}

ConfinedFile DatabaseDirectory::resolve(const std::string& requested, bool create_folders) const {
  if (requested.empty()) throw InvalidInput("empty database name");
  if (requested.size() > kMaxPathBytes) throw InvalidInput("database name longer than 4096 bytes");
  if (requested.find('\0') != std::string::npos) throw InvalidInput("database name contains a NUL byte");
  std::string relative = requested;
  if ((requested + "/").find("/../") != std::string::npos) {  // before the prefix check, which it would fool
    throw InvalidInput("database name '" + requested + "' must not contain '..'");
  }
  if (requested.front() == '/') {
    const std::string prefix = root_ == "/" ? "/" : root_ + "/";
    if (requested.compare(0, prefix.size(), prefix) != 0 || requested.size() == prefix.size()) {
      throw InvalidInput("database path " + requested + " lies outside the database folder " + root_ +
                         " (~database_dir)");
    }
    relative = requested.substr(prefix.size());
  }
  const std::vector<std::string> parts = components(relative, requested);
  if (parts.size() - 1 > limits_.max_depth) {
    throw InvalidInput("database name '" + requested + "' is " + std::to_string(parts.size() - 1) +
                       " folders deep; at most " + std::to_string(limits_.max_depth) + " are allowed");
  }
  if (isTemporaryFileName(parts.back())) {
    throw InvalidInput("database name '" + requested + "' is reserved: saves name their temporary files so");
  }
  for (const std::string& part : parts) {
    if (isTeamLedgerName(part)) {
      throw InvalidInput("database name '" + requested + "' is reserved: a team station saves its ledger so");
    }
  }
  if (create_folders && parts.back().size() > kMaxComponentBytes - kMaxTemporaryExtraBytes) {
    throw InvalidInput("database name '" + requested + "' ends in a name longer than " +
                       std::to_string(kMaxComponentBytes - kMaxTemporaryExtraBytes) +
                       " bytes: a save needs room for its temporary file's name beside it");
  }
  if (create_folders) checkRoomFor(parts, requested);

  int fd = ::open(root_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) throw IoError("database folder " + root_ + ": cannot open (" + errnoText(errno) + ")");
  std::string shown = root_;
  for (size_t i = 0; i + 1 < parts.size(); ++i) {
    shown += "/" + parts[i];
    int next = ::openat(fd, parts[i].c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (next < 0 && errno == ENOENT && create_folders) {
      if (::mkdirat(fd, parts[i].c_str(), 0755) != 0 && errno != EEXIST) {
        const int error = errno;
        ::close(fd);
        throw IoError(shown + ": cannot create the folder (" + errnoText(error) + ")");
      }
      next = ::openat(fd, parts[i].c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    }
    const int error = errno;
    ::close(fd);
    if (next < 0) {
      if (error == ELOOP || error == ENOTDIR) {
        throw InvalidInput(shown + " is not a folder (symbolic links are not followed inside the database folder)");
      }
      throw IoError(shown + ": cannot open (" + errnoText(error) + ")");
    }
    fd = next;
  }
  return ConfinedFile(fd, parts.back(), shown + "/" + parts.back());
}

void DatabaseDirectory::checkRoomFor(const std::vector<std::string>& parts, const std::string& requested) const {
  // What the save would add: the missing folders of its path and the file, unless it is replaced.
  size_t added = 0;
  fs::path path = root_;
  for (const std::string& part : parts) {
    path /= part;
    std::error_code error;
    if (added > 0 || !fs::exists(fs::symlink_status(path, error))) ++added;
  }
  // What the folder holds (symbolic links below it are counted, never followed), counted only as
  // far as the bound.
  size_t entries = 0;
  unsigned long long bytes = 0;
  std::error_code error;
  for (fs::recursive_directory_iterator it(root_, fs::directory_options::skip_permission_denied, error), end;
       !error && it != end; it.increment(error)) {
    if (++entries + added > limits_.max_entries) {
      throw InvalidInput("the database folder " + root_ + " holds " + std::to_string(limits_.max_entries) +
                         " or more files and folders (~max_database_files): refusing to save " + requested +
                         "; remove some, or save over an existing file");
    }
    std::error_code entry_error;
    const fs::file_status status = it->symlink_status(entry_error);
    if (entry_error || !fs::is_regular_file(status) || it->path() == path) continue;
    const auto size = it->file_size(entry_error);
    if (!entry_error) bytes += size;
    if (bytes >= limits_.max_bytes) {
      throw InvalidInput("the files in the database folder " + root_ + " hold " + std::to_string(bytes >> 20) +
                         " MB or more (~max_database_dir_mb): refusing to save " + requested + "; remove some first");
    }
  }
}

std::string DatabaseDirectory::describe(const std::string& requested) const {
  try {
    return resolve(requested).display();
  } catch (const Error&) {
    return "";
  }
}

}  // namespace mild
