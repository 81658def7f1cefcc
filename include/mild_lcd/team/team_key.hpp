#pragma once

// The key a team's stations share (~team/key_file, docs/multi_robot.md "The team key"): every team
// message carries an HMAC-SHA256 under it, so that a publisher without the key can neither inject
// nor alter one. The cryptography is OpenSSL's libcrypto.

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

namespace mild {

class TeamKey {
 public:
  static constexpr size_t kMacBytes = 32;
  static constexpr size_t kMinKeyBytes = 32;  // `openssl rand -hex 32` writes 64
  using Mac = std::array<uint8_t, kMacBytes>;

  // Throws InvalidInput for a secret shorter than kMinKeyBytes.
  explicit TeamKey(std::string secret);
  // The key in the file at `path`, its content without trailing white space. The file must be a
  // regular file (not a link, FIFO or device: never followed or waited on), owned by this
  // process's user and readable by nobody else (mode 0600 or 0400), else InvalidInput says why;
  // IoError when it cannot be read.
  static TeamKey fromFile(const std::string& path);

  Mac mac(const uint8_t* data, size_t size) const;
  // Whether `mac` (of `size` bytes) is data's, compared in constant time.
  bool verify(const uint8_t* data, size_t size, const uint8_t* mac, size_t mac_size) const;

 private:
  std::string secret_;
};

// A key file's content (at most 4 KB): a regular file (a link, FIFO or device is refused, never
// followed or waited on), owned by this process's user and readable by nobody else, else
// InvalidInput names `what` and why; IoError when it cannot be read.
std::string readOwnerOnlyFile(const std::string& path, const std::string& what);
// A public file of at most 4 KB named `name` in the open folder `folder_fd`, as above but readable by
// anyone. `display`: its path, for messages.
std::string readConfinedFile(int folder_fd, const std::string& name, const std::string& display);

}  // namespace mild
