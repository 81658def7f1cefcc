#include "mild_lcd/io/database_directory.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <vector>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

namespace fs = std::filesystem;

constexpr size_t kMaxPathBytes = 4096;
constexpr size_t kMaxComponentBytes = 255;

std::string errnoText(int error) { return std::strerror(error); }

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
