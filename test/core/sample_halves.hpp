#pragma once

// The embedded sample split in two, as robots or stations mapping its halves at the same time see
// it: frames 0..149 and 150..299, whose end comes back to the start.

#include <string>

#include "mild_lcd/offline/evaluation.hpp"
#include "test_images.hpp"

namespace mild::test {

constexpr int kSampleFrames = 300;
constexpr int kSampleHalf = 150;

// The ground truth's pairs from the second half to the first (the halves' shared places).
inline GroundTruth sampleAcrossHalves() {
  const GroundTruth all = loadGroundTruth(kSampleDir + "/gt_loops.txt", kSampleFrames);
  GroundTruth truth;
  for (const auto& p : all.right) {
    if (p.first >= kSampleHalf && p.second < kSampleHalf) {
      truth.right.insert(p);
      truth.loop_queries.insert(p.first);
    }
  }
  for (const auto& p : all.dont_care) {
    if (p.first >= kSampleHalf && p.second < kSampleHalf) truth.dont_care.insert(p);
  }
  return truth;
}

}  // namespace mild::test
