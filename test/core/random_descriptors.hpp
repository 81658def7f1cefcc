#pragma once

#include <algorithm>
#include <numeric>
#include <random>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"

namespace mild::test {

inline Descriptor randomDescriptor(std::mt19937_64& rng) {
  Descriptor d;
  for (auto& w : d.words) w = rng();
  return d;
}

// d with exactly `bits` distinct bit positions flipped.
inline Descriptor flipRandomBits(Descriptor d, int bits, std::mt19937_64& rng) {
  std::vector<int> positions(kDescriptorBits);
  std::iota(positions.begin(), positions.end(), 0);
  std::shuffle(positions.begin(), positions.end(), rng);
  for (int i = 0; i < bits; ++i) d.flip(positions[i]);
  return d;
}

inline DescriptorList randomDescriptors(size_t n, std::mt19937_64& rng) {
  DescriptorList out(n);
  for (auto& d : out) d = randomDescriptor(rng);
  return out;
}

}  // namespace mild::test
