#include "mild_lcd/index/substring_layout.hpp"

#include <algorithm>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

void addMasks(int length, int radius, int first_bit, uint64_t mask, std::vector<uint64_t>& out) {
  out.push_back(mask);
  if (radius == 0) return;
  for (int b = first_bit; b < length; ++b) addMasks(length, radius - 1, b + 1, mask | (uint64_t{1} << b), out);
}

}  // namespace

SubstringLayout::SubstringLayout(int num_substrings, int bits) : bits_(bits) {
  if (bits % 8 != 0) throw InvalidInput("descriptor width must be whole bytes, got " + std::to_string(bits) + " bits");
  checkDescriptorBytes(bits / 8);
  const int fewest = std::max(kMinSubstrings, substringsFor(bits, kMaxSubstringBits));
  if (num_substrings < fewest || num_substrings > kMaxSubstrings) {
    throw InvalidInput("number of hash tables (substrings) for " + std::to_string(bits) +
                       "-bit descriptors must be in [" + std::to_string(fewest) + ", " +
                       std::to_string(kMaxSubstrings) + "], got " + std::to_string(num_substrings));
  }
  const int base = bits / num_substrings;
  const int longer = bits % num_substrings;
  int offset = 0;
  for (int t = 0; t < num_substrings; ++t) {
    const int len = base + (t < longer ? 1 : 0);
    Descriptor m(bits / 8);
    for (int b = offset; b < offset + len; ++b) m.flip(b);
    offsets_.push_back(offset);
    lengths_.push_back(len);
    masks_.push_back(m);
    Extract e;
    e.word = offset >> 6;
    e.shift = offset & 63;
    e.spans = e.shift + len > 64;
    e.mask = len == 64 ? ~uint64_t{0} : (uint64_t{1} << len) - 1;
    extract_.push_back(e);
    offset += len;
  }
}

std::vector<std::vector<uint64_t>> SubstringLayout::probeMasks(int radius) const {
  std::vector<std::vector<uint64_t>> masks(static_cast<size_t>(maxLength()) + 1);
  for (int len : lengths_) {
    if (masks[len].empty()) addMasks(len, std::min(radius, len), 0, 0, masks[len]);
  }
  return masks;
}

}  // namespace mild
