#pragma once

#include <string>
#include <vector>

#include "mild_lcd/verification/relative_pose.hpp"

namespace mild {

// A camera pose on the ground plane, as the bench's poses.txt gives it: x, y in metres, yaw in
// radians, the camera looking along (cos yaw, sin yaw) with its y axis pointing down (world z up).
struct PlanarPose {
  double x = 0.0, y = 0.0, yaw = 0.0;
};

// One "x y yaw" line per frame; throws InvalidInput naming the file and line when malformed or when
// the count differs from expected_frames (negative: unchecked).
std::vector<PlanarPose> loadPlanarPoses(const std::string& path, long expected_frames = -1);

// The candidate camera's pose in the query camera's frame, with RelativePose's conventions; the
// translation is a unit vector (zero when the centres coincide).
RelativePose groundTruthRelativePose(const PlanarPose& query, const PlanarPose& candidate);

// Rotation and baseline-direction errors of estimated relative poses against ground truth.
struct PoseErrors {
  std::vector<double> rotation_deg;
  std::vector<double> translation_deg;  // only pairs whose baseline is at least min_baseline_m
  double min_baseline_m = 0.5;
  void add(const RelativePose& estimate, const PlanarPose& query, const PlanarPose& candidate);
};

}  // namespace mild
