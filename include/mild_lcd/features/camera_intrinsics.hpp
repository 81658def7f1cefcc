#pragma once

#include <cmath>

#include <opencv2/core.hpp>

namespace mild {

// Pinhole intrinsics of the camera a keyframe was taken with, in pixels (sensor_msgs/CameraInfo's
// K: fx, fy, cx, cy). All zero means unknown. Keypoints are taken as undistorted: lens distortion
// is not modelled here (feed rectified images, or undistorted keypoints).
struct CameraIntrinsics {
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;

  bool known() const { return fx > 0.0; }
  // Unknown (all zero), or focal lengths positive and every value finite.
  bool wellFormed() const {
    if (fx == 0.0 && fy == 0.0 && cx == 0.0 && cy == 0.0) return true;
    return fx > 0.0 && fy > 0.0 && std::isfinite(fx) && std::isfinite(fy) && std::isfinite(cx) && std::isfinite(cy);
  }
  cv::Matx33d matrix() const { return {fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0}; }
  bool operator==(const CameraIntrinsics& o) const { return fx == o.fx && fy == o.fy && cx == o.cx && cy == o.cy; }
  bool operator!=(const CameraIntrinsics& o) const { return !(*this == o); }
};

}  // namespace mild
