#include "mild_lcd/index/substring_layout.hpp"

#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

SubstringLayout::SubstringLayout(int num_substrings) {
  if (num_substrings < kMinSubstrings || num_substrings > kMaxSubstrings) {
    throw InvalidInput("number of hash tables (substrings) must be in [" + std::to_string(kMinSubstrings) + ", " +
                       std::to_string(kMaxSubstrings) + "], got " + std::to_string(num_substrings));
  }
  const int base = kDescriptorBits / num_substrings;
  const int longer = kDescriptorBits % num_substrings;
  int offset = 0;
  for (int t = 0; t < num_substrings; ++t) {
    const int len = base + (t < longer ? 1 : 0);
    Descriptor m;
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

}  // namespace mild
