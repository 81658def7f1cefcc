#pragma once

// One keyframe as it enters the pipeline, whatever it arrived as: what each input adapter of the
// ROS layer (ros/keyframe_input.hpp) produces from its message, what a FeatureFrontEnd turns from
// an image into features, and what LoopDetector::process and RobotTeam::process take (features
// only). A new field reaches every stage that takes the observation; a new input kind is one adapter.

#include <cstddef>
#include <cstdint>
#include <optional>

#include <opencv2/core.hpp>

#include "mild_lcd/features/features.hpp"

namespace mild {

// An image a FeatureFrontEnd (features/type) turns into features.
struct ObservedImage {
  cv::Mat pixels;
  PixelFormat format = PixelFormat::kGray;
};

struct Observation {
  // Keypoints, descriptors, the camera's intrinsics and optional depths (features.hpp). With an
  // image, only the camera: the features are extracted from the image.
  Features features;
  std::optional<ObservedImage> image;
  double stamp = 0.0;
  std::optional<uint64_t> id;  // the sender's id, or the next free one
  size_t robot = 0;            // whose keyframe (the index in the RobotTeam; 0 for one robot). The
                               // session is the robot's detector's (KeyframeMap::session).
  // Features extracted from an image (FeatureFrontEnd::extract): how long that took, reported as
  // DetectionResult::stats.extract_ms. 0 for features that arrived as such.
  double extract_ms = 0.0;

  static Observation ofFeatures(Features features, double stamp, std::optional<uint64_t> id = std::nullopt,
                                size_t robot = 0) {
    Observation o;
    o.features = std::move(features);
    o.stamp = stamp;
    o.id = id;
    o.robot = robot;
    return o;
  }
  static Observation ofImage(cv::Mat pixels, PixelFormat format, double stamp,
                             std::optional<uint64_t> id = std::nullopt, const CameraIntrinsics& camera = {},
                             size_t robot = 0) {
    Observation o;
    o.image = ObservedImage{std::move(pixels), format};
    o.features.camera = camera;
    o.stamp = stamp;
    o.id = id;
    o.robot = robot;
    return o;
  }
};

}  // namespace mild
