#include "mild_lcd/team/team_key.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>

#include "mild_lcd/common/errors.hpp"

namespace mild {

TeamKey::TeamKey(std::string secret) : secret_(std::move(secret)) {
  if (secret_.size() < kMinKeyBytes) {
    throw InvalidInput("a team key needs at least " + std::to_string(kMinKeyBytes) + " bytes, got " +
                       std::to_string(secret_.size()) + " (make one with: openssl rand -hex 32)");
  }
}

namespace {

// The file opened at `fd` (a regular file, at most 4 KB), whole; `owner_only`: owned by this
// process's user and readable by nobody else. Closes fd.
std::string readSmallFile(int fd, const std::string& display, const std::string& what, bool owner_only) {
  struct stat st {};
  std::string why;
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    why = "is not a regular file";
  } else if (owner_only && st.st_uid != ::geteuid()) {
    why =
        "is owned by user " + std::to_string(st.st_uid) + ", not by this process's user " + std::to_string(::geteuid());
  } else if (owner_only && (st.st_mode & 077) != 0) {
    why = "can be read or written by others than its owner (chmod 600 it)";
  } else if (st.st_size > 4096) {
    why = "is larger than any key (4 KB)";
  }
  if (!why.empty()) {
    ::close(fd);
    throw InvalidInput(what + " " + display + " " + why);
  }
  std::string text(static_cast<size_t>(st.st_size), '\0');
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::read(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    done += static_cast<size_t>(n);
  }
  ::close(fd);
  text.resize(done);
  return text;
}

// O_NOFOLLOW: a link is refused; O_NONBLOCK: opening a FIFO never waits for a writer.
constexpr int kOpenFlags = O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC;

int openOrThrow(int fd, const std::string& display, const std::string& what) {
  if (fd >= 0) return fd;
  const int error = errno;
  if (error == ELOOP) throw InvalidInput(what + " " + display + " is a symbolic link");
  throw IoError("cannot open the " + what + " " + display + ": " + std::strerror(error));
}

}  // namespace

std::string readOwnerOnlyFile(const std::string& path, const std::string& what) {
  return readSmallFile(openOrThrow(::open(path.c_str(), kOpenFlags), path, what), path, what, true);
}

std::string readConfinedFile(int folder_fd, const std::string& name, const std::string& display) {
  const std::string what = "team roster file";
  return readSmallFile(openOrThrow(::openat(folder_fd, name.c_str(), kOpenFlags), display, what), display, what, false);
}

TeamKey TeamKey::fromFile(const std::string& path) {
  std::string text = readOwnerOnlyFile(path, "team key file");
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ' || text.back() == '\t')) {
    text.pop_back();
  }
  return TeamKey(std::move(text));
}

TeamKey::Mac TeamKey::mac(const uint8_t* data, size_t size) const {
  Mac out{};
  unsigned int length = 0;
  if (HMAC(EVP_sha256(), secret_.data(), static_cast<int>(secret_.size()), data, size, out.data(), &length) ==
          nullptr ||
      length != kMacBytes) {
    throw IoError("HMAC-SHA256 failed (libcrypto)");
  }
  return out;
}

bool TeamKey::verify(const uint8_t* data, size_t size, const uint8_t* mac, size_t mac_size) const {
  if (mac_size != kMacBytes) return false;
  const Mac expected = this->mac(data, size);
  return CRYPTO_memcmp(expected.data(), mac, kMacBytes) == 0;
}

}  // namespace mild
