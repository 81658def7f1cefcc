#pragma once

#include <opencv2/core.hpp>

#include "mild_lcd/features/features.hpp"

namespace mild {

// Where a keyframe's features come from when the detector is given an image. Every implementation
// produces binary descriptors of one width, which becomes the width of the database. Implementations
// (orb_extractor.hpp, brisk_extractor.hpp, akaze_extractor.hpp) wrap OpenCV detectors, which keep
// state: not thread-safe, one per thread.
class FeatureExtractor {
 public:
  virtual ~FeatureExtractor() = default;
  virtual const char* name() const = 0;
  virtual int descriptorBytes() const = 0;
  // Any image size works; an image too small for the detector's border yields no features. Throws
  // InvalidInput for an unusable image.
  virtual Features extract(const cv::Mat& image, PixelFormat format) const = 0;
};

}  // namespace mild
