#pragma once

#include <cstdint>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"

namespace mild {

// How a descriptor of `bits` bits is cut into m disjoint, contiguous substrings for multi-index
// hashing. When m does not divide the width, the first (bits mod m) substrings are one bit longer
// than the others, so lengths differ by at most one bit. Substrings are 1 to 64 bits long, so m is
// at least bits / 64 (4 for ORB's 256 bits, 8 for BRISK's 512).
class SubstringLayout {
 public:
  static constexpr int kMinSubstrings = 4;
  static constexpr int kMaxSubstrings = 64;
  static constexpr int kMaxSubstringBits = 64;

  // Throws InvalidInput when num_substrings is outside [kMinSubstrings, kMaxSubstrings], would cut
  // substrings longer than 64 bits, or bits is not a supported descriptor width.
  SubstringLayout(int num_substrings, int bits);

  // The fewest substrings that cut `bits` into pieces of at most max_length bits.
  static int substringsFor(int bits, int max_length) { return (bits + max_length - 1) / max_length; }

  int bits() const { return bits_; }
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

  // The descriptor bits that substring t covers, as a mask of the layout's width.
  const Descriptor& mask(int t) const { return masks_[t]; }

  // Multi-probe: for each substring length in use (index = length), the XOR masks of popcount <= r,
  // i.e. the buckets within Hamming distance r of a substring. Shared by the MIH index and sparse
  // match, so the two probe exactly alike.
  std::vector<std::vector<uint64_t>> probeMasks(int radius) const;

 private:
  // Precomputed bit extraction per substring: key() is on every hot path.
  struct Extract {
    int word = 0;
    int shift = 0;
    bool spans = false;  // continues into the next word
    uint64_t mask = 0;
  };
  int bits_ = 0;
  std::vector<int> offsets_;
  std::vector<int> lengths_;
  std::vector<Descriptor> masks_;
  std::vector<Extract> extract_;
};

}  // namespace mild
