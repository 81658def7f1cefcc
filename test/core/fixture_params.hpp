#pragma once

// The detector's parameters for the fixture (test_images.hpp: every 5th frame of the sample), shared
// by the core and ROS tests.

#include "mild_lcd/detector/loop_detector.hpp"

namespace mild::test {

// The defaults with the exclusion scaled to the fixture's stride: the bench's 40 frames are 8 of its
// keyframes (the revisit is at 47-59).
inline DetectorParams fixtureParams() {
  DetectorParams p;
  p.candidates.exclusion_frames = 8;
  return p;
}

}  // namespace mild::test
