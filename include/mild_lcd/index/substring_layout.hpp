#pragma once

#include <cstdint>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"

namespace mild {

// How a 256-bit descriptor is cut into m disjoint, contiguous substrings for multi-index hashing.
// When m does not divide 256, the first (256 mod m) substrings are one bit longer than the others,
// so lengths differ by at most one bit. Substrings longer than 64 bits are not supported (m >= 4).
class SubstringLayout {
 public:
  static constexpr int kMinSubstrings = 4;
  static constexpr int kMaxSubstrings = 64;

  // Throws InvalidInput when num_substrings is outside [kMinSubstrings, kMaxSubstrings].
  explicit SubstringLayout(int num_substrings);

  int count() const { return static_cast<int>(offsets_.size()); }
  int offset(int t) const { return offsets_[t]; }
  int length(int t) const { return lengths_[t]; }
  int maxLength() const { return lengths_.front(); }

  // The value of substring t of d (bits offset(t) .. offset(t)+length(t)-1, least significant first).
  uint64_t key(const Descriptor& d, int t) const {
    const Extract& e = extract_[t];
    uint64_t v = d.words[e.word] >> e.shift;
    if (e.spans) v |= d.words[e.word + 1] << (64 - e.shift);
    return v & e.mask;
  }

  // The descriptor bits that substring t covers, as a 256-bit mask.
  const Descriptor& mask(int t) const { return masks_[t]; }

 private:
  // Precomputed bit extraction per substring: key() is on every hot path.
  struct Extract {
    int word = 0;
    int shift = 0;
    bool spans = false;  // continues into the next word
    uint64_t mask = 0;
  };
  std::vector<int> offsets_;
  std::vector<int> lengths_;
  std::vector<Descriptor> masks_;
  std::vector<Extract> extract_;
};

}  // namespace mild
