#pragma once

#include <memory>

#include "mild_lcd/features/feature_extractor.hpp"

namespace mild {

// features/max_pixels: frames larger than `max_pixels` are converted to grey and shrunk (area
// averaging, aspect kept) to at most that many pixels before `inner` extracts from them, and the keypoints are mapped
// back to the frame's pixels (position and size), so that everything downstream (verification, relative pose, published
// correspondences, the camera's intrinsics) stays in the frame's own pixels. An extractor's cost grows with the pixels
// it reads: a cap makes it one cost whatever the camera (AKAZE on 640 x 360 frames: about 140 ms per keyframe in full,
// under 30 ms at 320 x 240 with one sub-level per octave, docs/accuracy.md). Frames at or below the cap pass unchanged.
// The features record the shrink as Features::detection_scale, by which verification widens its pixel tolerances (its
// fit's and the chance agreement's; homography_share, a published description of the inliers, keeps 3 pixels).
class ResolutionCap : public FeatureExtractor {
 public:
  ResolutionCap(std::unique_ptr<FeatureExtractor> inner, double max_pixels);
  const char* name() const override { return inner_->name(); }
  int descriptorBytes() const override { return inner_->descriptorBytes(); }
  Features extract(const cv::Mat& image, PixelFormat format) const override;
  // The size a frame of `frame` pixels is shrunk to: the aspect kept, at most max_pixels pixels,
  // no side below one pixel.
  static cv::Size shrunkSize(const cv::Size& frame, double max_pixels);

 private:
  std::unique_ptr<FeatureExtractor> inner_;
  double max_pixels_;
};

}  // namespace mild
