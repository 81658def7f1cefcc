#pragma once

// One keyframe as it enters the pipeline, whatever it arrived as: what RobotTeam::process takes,
// and what each input adapter of the ROS layer (ros/keyframe_input.hpp) produces from its message.
// A new field reaches every stage that takes the observation; a new input kind is one adapter.

#include <cstddef>
#include <cstdint>
#include <optional>

#include <opencv2/core.hpp>

#include "mild_lcd/features/feature_extractor.hpp"
#include "mild_lcd/features/features.hpp"

namespace mild {

// An image the detector's extractor (features/type) turns into features.
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
                               // session is the robot's detector's (LoopDetector::session).
  // Features extracted from an image before the observation reached the detector
  // (extractFeatures): how long that took, reported as DetectionResult::stats.extract_ms. 0 for
  // features that arrived as such.
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

// An image observation turned into a feature one: `extractor`'s features of its image, with its
// camera, stamp, id and robot, and extract_ms the time the extraction took. The one extraction step
// of the pipeline: LoopDetector::process runs it on an image under its caller's lock, the ROS
// worker on a thread of its own ahead of the detector (with an extractor of its own, built from the
// same features/ parameters: extractors are not thread-safe). An observation without an image is
// returned unchanged. Throws InvalidInput for an unusable image, or when the extractor's descriptors
// are not `descriptor_bytes` wide (the database's width: features/descriptor_bytes set for a
// front-end's descriptors refuses images).
Observation extractFeatures(Observation observation, const FeatureExtractor& extractor, int descriptor_bytes);

}  // namespace mild
