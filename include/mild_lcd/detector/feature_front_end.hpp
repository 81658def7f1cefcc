#pragma once

// The one place an image becomes features: an extractor built from the detector's features/
// parameters and the check that its descriptors have the map's width. Whoever feeds images owns
// one (the ROS worker one per worker, each offline tool one); the detector takes features only
// (LoopDetector::process), so no keyframe is ever extracted twice or under the detector's lock.
// Not thread-safe, as extractors are not: one per thread.

#include <memory>

#include "mild_lcd/detector/observation.hpp"
#include "mild_lcd/features/feature_extractor.hpp"
#include "mild_lcd/features/feature_source.hpp"

namespace mild {

class FeatureFrontEnd {
 public:
  // Throws InvalidInput for invalid features/ parameters.
  explicit FeatureFrontEnd(const FeatureParams& features);

  // An image observation turned into a feature one: the extractor's features of its image, with its
  // camera, stamp, id and robot, and extract_ms the time the extraction took. An observation
  // without an image is returned unchanged. Throws InvalidInput for an unusable image, or when the
  // extractor's descriptors are not the map's width (features/descriptor_bytes set for a
  // front-end's descriptors refuses images).
  Observation extract(Observation observation) const;

  // The width every map of these parameters stores, in bytes.
  int descriptorBytes() const { return descriptor_bytes_; }
  const FeatureExtractor& extractor() const { return *extractor_; }

 private:
  std::unique_ptr<FeatureExtractor> extractor_;
  int descriptor_bytes_;
};

}  // namespace mild
