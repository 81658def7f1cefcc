#pragma once

// A station's name bound to a key of its own (docs/multi_robot.md, "Station names bound to keys"):
// each station signs every team message with its Ed25519 private key (~team/station_key_file), and
// each checks a message claiming to be from station X against X's public key in the team's roster
// (~team/roster_dir: one "<station>.pub" PEM file per station). Holding the team key (team_key.hpp)
// makes a publisher a member; only X's private key makes it X. The cryptography is OpenSSL's
// libcrypto.

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "mild_lcd/team/team_key.hpp"

namespace mild {

struct PublicKeyDeleter {
  void operator()(void* key) const;
};
using PublicKeyHandle = std::unique_ptr<void, PublicKeyDeleter>;  // an EVP_PKEY

class StationSigner {
 public:
  static constexpr size_t kSignatureBytes = 64;
  using Signature = std::array<uint8_t, kSignatureBytes>;

  // The Ed25519 private key (PEM) in the file at `path`, which must be a regular file owned by this
  // process's user and readable by nobody else (as the team key); else InvalidInput says why.
  static StationSigner fromFile(const std::string& path);
  Signature sign(const uint8_t* data, size_t size) const;

 private:
  explicit StationSigner(PublicKeyHandle key) : key_(std::move(key)) {}
  PublicKeyHandle key_;
};

class StationRoster {
 public:
  static constexpr size_t kMaxStations = 64;

  // Every "<station>.pub" (an Ed25519 public key, PEM) in the folder at `path`: regular files (a
  // link, FIFO or device is refused, never followed or waited on) of at most 4 KB, named by valid
  // station names; at most kMaxStations. Throws InvalidInput naming the file at fault, IoError when
  // the folder cannot be read.
  static StationRoster fromFolder(const std::string& path);

  bool has(const std::string& station) const { return keys_.count(station) > 0; }
  size_t size() const { return keys_.size(); }
  // Whether `signature` is `station`'s over data (false for a station not in the roster).
  bool verify(const std::string& station, const uint8_t* data, size_t size, const uint8_t* signature,
              size_t signature_size) const;

 private:
  std::map<std::string, PublicKeyHandle> keys_;
};

// What authenticates a station's team messages: the team key (membership), and its signing key
// with the team's roster (its name). Any of them may be absent; the station's key and the roster
// go together.
class TeamCredentials {
 public:
  TeamCredentials() = default;  // none: anyone can send anything (warned about)
  // Reads the files that are named (an empty path: none). Throws InvalidInput when only one of
  // station_key_file and roster_dir is given, or when the roster's key for `station` is not the
  // one station_key_file holds; and as the readers do.
  static TeamCredentials fromFiles(const std::string& team_key_file, const std::string& station_key_file,
                                   const std::string& roster_dir, const std::string& station);

  bool any() const { return key_.has_value() || roster_.has_value(); }
  bool keyed() const { return key_.has_value(); }
  const StationRoster* roster() const { return roster_ ? &*roster_ : nullptr; }
  // The authentication of `data`: its HMAC under the team key (32 bytes, with a key), then this
  // station's signature (64 bytes, with a roster). Empty with neither.
  std::vector<uint8_t> seal(const uint8_t* data, size_t size) const;
  // Whether `seal` is what `sender` (with its key, from the roster) would seal data with. The team
  // key's MAC is checked first: a forged flood costs no signature check.
  bool verify(const std::string& sender, const uint8_t* data, size_t size, const std::vector<uint8_t>& seal) const;

 private:
  std::optional<TeamKey> key_;
  std::optional<StationSigner> signer_;
  std::optional<StationRoster> roster_;
};

}  // namespace mild
