#pragma once

#include <algorithm>
#include <numeric>
#include <random>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"

namespace mild::test {

// A uniformly random descriptor of `bytes` bytes (ORB's 32 by default); bits past the width zero.
inline Descriptor randomDescriptor(std::mt19937_64& rng, int bytes = kOrbDescriptorBytes) {
  Descriptor d(bytes);
  for (int b = 0; b < d.bits(); ++b) {
    if (rng() & 1u) d.flip(b);
  }
  return d;
}

// d with exactly `bits` distinct bit positions flipped.
inline Descriptor flipRandomBits(Descriptor d, int bits, std::mt19937_64& rng) {
  std::vector<int> positions(d.bits());
  std::iota(positions.begin(), positions.end(), 0);
  std::shuffle(positions.begin(), positions.end(), rng);
  for (int i = 0; i < bits; ++i) d.flip(positions[i]);
  return d;
}

inline DescriptorList randomDescriptors(size_t n, std::mt19937_64& rng, int bytes = kOrbDescriptorBytes) {
  DescriptorList out(n);
  for (auto& d : out) d = randomDescriptor(rng, bytes);
  return out;
}

}  // namespace mild::test
