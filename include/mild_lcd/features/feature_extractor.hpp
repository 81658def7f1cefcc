#pragma once

#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include "mild_lcd/features/camera_intrinsics.hpp"
#include "mild_lcd/features/descriptor.hpp"

namespace mild {

// Channel order of an 8-bit input image.
enum class PixelFormat { kGray, kBgr, kRgb, kBgra, kRgba };

struct OrbParams {
  int num_features = 800;     // upper bound per keyframe (seed paper: up to 800)
  double scale_factor = 1.2;  // pyramid decimation ratio
  int num_levels = 8;         // pyramid levels
  int fast_threshold = 10;    // FAST corner threshold (grey levels)
  int edge_threshold = 31;    // border without features (px); also the patch size

  void validate() const;  // throws InvalidInput naming the first invalid field
};

// Keypoints and their 256-bit descriptors, row i of one describing keypoint i of the other.
// Optionally the camera's intrinsics, and each keypoint's depth (metres along the optical axis,
// from a depth camera or the front-end's triangulation; 0 or not finite = unknown), which make the
// relative pose of a loop metric (PnP) instead of up to scale.
struct Features {
  std::vector<cv::KeyPoint> keypoints;
  DescriptorList descriptors;
  CameraIntrinsics camera;
  std::vector<float> depths;  // empty, or one per keypoint
};

// Throws InvalidInput, naming the problem, when the camera is malformed (CameraIntrinsics::wellFormed)
// or there are depths but not one per keypoint.
void checkCameraAndDepths(const Features& features);

// Converts an 8-bit image of the given format to one grey channel. Throws InvalidInput for an empty
// image, a depth other than 8 bits, or a channel count that does not match the format.
cv::Mat toGray(const cv::Mat& image, PixelFormat format);

// OpenCV ORB with the package's parameters. Not thread-safe (OpenCV's detector keeps state); use
// one per thread.
class OrbExtractor {
 public:
  explicit OrbExtractor(const OrbParams& params = {});
  const OrbParams& params() const { return params_; }

  // Any image size works; an image too small for the border yields no features.
  Features extract(const cv::Mat& image, PixelFormat format = PixelFormat::kGray) const;

 private:
  OrbParams params_;
  cv::Ptr<cv::ORB> orb_;
};

}  // namespace mild
