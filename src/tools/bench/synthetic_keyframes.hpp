#pragma once

// Large keyframe databases made from real ORB descriptors, for mild_bench_scale. Uniform random bits
// would make MIH look unrealistically good (real substrings are skewed: some patterns are far more
// common), so every synthetic keyframe is a real frame's descriptors, each with a few random bits
// flipped, in shuffled order, topped up with another real frame's descriptors to the requested
// count. Replicas of one frame then relate like revisits of one place.

#include <cstdint>
#include <random>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"

namespace mild::tools {

class SyntheticKeyframes {
 public:
  // `frames`: descriptors of real frames (at least one non-empty).
  SyntheticKeyframes(std::vector<DescriptorList> frames, size_t features_per_keyframe, int min_flips = 8,
                     int max_flips = 24);

  // Keyframe k of the synthetic sequence; the same k always gives the same descriptors.
  DescriptorList keyframe(uint64_t k) const;
  // A query that revisits the place of real frame `frame` (not stored as such).
  DescriptorList query(uint64_t q) const;

  size_t realFrames() const { return frames_.size(); }

 private:
  DescriptorList replicate(const DescriptorList& main, const DescriptorList& filler, std::mt19937_64& rng) const;

  std::vector<DescriptorList> frames_;
  size_t features_;
  int min_flips_, max_flips_;
};

}  // namespace mild::tools
