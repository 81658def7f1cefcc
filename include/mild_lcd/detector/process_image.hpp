#pragma once

// For code that starts from one image at a time (a test, an example, a short script): a
// FeatureFrontEnd of the detector's own features/ parameters, built for the call, then the one
// process step. A loop over many images (the ROS worker, the offline tools) holds a
// FeatureFrontEnd instead and hands LoopDetector::process / RobotTeam::process its observations.

#include <cstdint>
#include <optional>

#include <opencv2/core.hpp>

#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/detector/robot_team.hpp"

namespace mild {

// Throws what FeatureFrontEnd::extract and LoopDetector::process throw; changes nothing then.
DetectionResult processImage(LoopDetector& detector, const cv::Mat& image, PixelFormat format, double stamp,
                             std::optional<uint64_t> id = std::nullopt, const CameraIntrinsics& camera = {});
DetectionResult processImage(RobotTeam& team, size_t robot, const cv::Mat& image, PixelFormat format, double stamp,
                             std::optional<uint64_t> id = std::nullopt, const CameraIntrinsics& camera = {});

}  // namespace mild
