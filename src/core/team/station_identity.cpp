#include "mild_lcd/team/station_identity.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

#include <openssl/bio.h>
#include <openssl/evp.h>
#include <openssl/pem.h>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/team/station_ledger.hpp"
#include "mild_lcd/team/team_key.hpp"

namespace mild {
namespace {

constexpr const char* kPublicKeySuffix = ".pub";

struct ContextDeleter {
  void operator()(EVP_MD_CTX* ctx) const { EVP_MD_CTX_free(ctx); }
};
using Context = std::unique_ptr<EVP_MD_CTX, ContextDeleter>;

struct BioDeleter {
  void operator()(BIO* bio) const { BIO_free(bio); }
};

EVP_PKEY* pkey(const PublicKeyHandle& key) { return static_cast<EVP_PKEY*>(key.get()); }

PublicKeyHandle readPem(const std::string& text, bool private_key, const std::string& path) {
  const std::unique_ptr<BIO, BioDeleter> bio(BIO_new_mem_buf(text.data(), static_cast<int>(text.size())));
  if (!bio) throw IoError("libcrypto could not read " + path);
  EVP_PKEY* key = private_key ? PEM_read_bio_PrivateKey(bio.get(), nullptr, nullptr, nullptr)
                              : PEM_read_bio_PUBKEY(bio.get(), nullptr, nullptr, nullptr);
  PublicKeyHandle handle(key);
  if (!key || EVP_PKEY_id(key) != EVP_PKEY_ED25519) {
    throw InvalidInput(path + " is not an Ed25519 " + std::string(private_key ? "private" : "public") +
                       " key in PEM (make one with: openssl genpkey -algorithm ed25519)");
  }
  return handle;
}

}  // namespace

void PublicKeyDeleter::operator()(void* key) const { EVP_PKEY_free(static_cast<EVP_PKEY*>(key)); }

StationSigner StationSigner::fromFile(const std::string& path) {
  return StationSigner(readPem(readOwnerOnlyFile(path, "station key file"), true, path));
}

StationSigner::Signature StationSigner::sign(const uint8_t* data, size_t size) const {
  Signature out{};
  size_t length = out.size();
  const Context ctx(EVP_MD_CTX_new());
  if (!ctx || EVP_DigestSignInit(ctx.get(), nullptr, nullptr, nullptr, pkey(key_)) != 1 ||
      EVP_DigestSign(ctx.get(), out.data(), &length, data, size) != 1 || length != kSignatureBytes) {
    throw IoError("Ed25519 signing failed (libcrypto)");
  }
  return out;
}

StationRoster StationRoster::fromFolder(const std::string& path) {
  // O_NOFOLLOW | O_DIRECTORY: the folder itself is not a link; its files are opened relative to it.
  const int folder = ::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
  if (folder < 0) throw IoError("cannot open the team roster folder " + path + ": " + std::strerror(errno));
  DIR* dir = ::fdopendir(folder);
  if (!dir) {
    ::close(folder);
    throw IoError("cannot read the team roster folder " + path);
  }
  std::vector<std::string> names;
  while (const dirent* entry = ::readdir(dir)) {
    const std::string name = entry->d_name;
    const size_t suffix = std::strlen(kPublicKeySuffix);
    if (name.size() > suffix && name.compare(name.size() - suffix, suffix, kPublicKeySuffix) == 0) {
      names.push_back(name);
    }
  }
  StationRoster roster;
  try {
    for (const std::string& name : names) {
      const std::string station = name.substr(0, name.size() - std::strlen(kPublicKeySuffix));
      const std::string file = path + "/" + name;
      if (!validStationName(station)) throw InvalidInput(file + ": '" + station + "' is not a station name");
      if (roster.keys_.size() == kMaxStations) {
        throw InvalidInput("the team roster " + path + " names more than " + std::to_string(kMaxStations) +
                           " stations");
      }
      roster.keys_.emplace(station, readPem(readConfinedFile(::dirfd(dir), name, file), false, file));
    }
  } catch (...) {
    ::closedir(dir);
    throw;
  }
  ::closedir(dir);
  if (roster.keys_.empty()) throw InvalidInput("the team roster " + path + " holds no <station>.pub file");
  return roster;
}

bool StationRoster::verify(const std::string& station, const uint8_t* data, size_t size, const uint8_t* signature,
                           size_t signature_size) const {
  const auto it = keys_.find(station);
  if (it == keys_.end() || signature_size != StationSigner::kSignatureBytes) return false;
  const Context ctx(EVP_MD_CTX_new());
  return ctx && EVP_DigestVerifyInit(ctx.get(), nullptr, nullptr, nullptr, pkey(it->second)) == 1 &&
         EVP_DigestVerify(ctx.get(), signature, signature_size, data, size) == 1;
}

TeamCredentials TeamCredentials::fromFiles(const std::string& team_key_file, const std::string& station_key_file,
                                           const std::string& roster_dir, const std::string& station) {
  TeamCredentials c;
  if (!team_key_file.empty()) c.key_ = TeamKey::fromFile(team_key_file);
  if (station_key_file.empty() != roster_dir.empty()) {
    throw InvalidInput("~team/station_key_file and ~team/roster_dir go together: set both or neither");
  }
  if (roster_dir.empty()) return c;
  c.signer_ = StationSigner::fromFile(station_key_file);
  c.roster_ = StationRoster::fromFolder(roster_dir);
  const uint8_t probe[] = {'m', 'i', 'l', 'd'};
  const StationSigner::Signature s = c.signer_->sign(probe, sizeof probe);
  if (!c.roster_->verify(station, probe, sizeof probe, s.data(), s.size())) {
    throw InvalidInput(station_key_file + " is not the private key of " + roster_dir + "/" + station +
                       ".pub (or the roster has no " + station + ".pub)");
  }
  return c;
}

std::vector<uint8_t> TeamCredentials::seal(const uint8_t* data, size_t size) const {
  std::vector<uint8_t> out;
  if (key_) {
    const TeamKey::Mac mac = key_->mac(data, size);
    out.assign(mac.begin(), mac.end());
  }
  if (signer_) {
    const StationSigner::Signature s = signer_->sign(data, size);
    out.insert(out.end(), s.begin(), s.end());
  }
  return out;
}

bool TeamCredentials::verify(const std::string& sender, const uint8_t* data, size_t size,
                             const std::vector<uint8_t>& seal) const {
  const size_t hmac = key_ ? TeamKey::kMacBytes : 0;
  if (seal.size() != hmac + (roster_ ? StationSigner::kSignatureBytes : 0)) return false;
  if (key_ && !key_->verify(data, size, seal.data(), hmac)) return false;
  return !roster_ || roster_->verify(sender, data, size, seal.data() + hmac, seal.size() - hmac);
}

}  // namespace mild
