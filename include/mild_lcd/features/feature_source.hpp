#pragma once

#include <memory>
#include <string>
#include <vector>

#include "mild_lcd/features/extractors.hpp"
#include "mild_lcd/features/feature_extractor.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

// The names features/type accepts (FeatureExtractors' entries).
const std::vector<std::string>& featureTypes();

// The smallest features/max_pixels (64 x 64): below it detectors find next to nothing.
constexpr double kMinCappedPixels = 4096.0;

// The feature source of a detector: `type` names the extractor (features/type), whose own
// parameters sit in its section (`extractors`: one per FeatureExtractors entry).
struct FeatureParams {
  std::string type = "orb";
  int descriptor_bytes = 0;
  double reference_pixels = 76800.0;
  double max_pixels = 0.0;
  FeatureExtractors::Sections extractors;

  static constexpr const char* kSection = "features";
  static constexpr const char* kDoc = "Where a keyframe's features come from when the node is given images.";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("type", p.type, Bounds::oneOf(featureTypes()),
      "The feature extractor for image input, one of the sections below (each states its descriptor width). Its "
      "descriptor width becomes the database's, and the saved map's: a map is loaded only by a detector of the "
      "same width.");
    v("descriptor_bytes", p.descriptor_bytes, Bounds::in(kMinDescriptorBytes, kMaxDescriptorBytes).orZero(),
      "Width of the stored descriptors in bytes; 0 = the extractor's. Another value serves Keyframe input from a "
      "front-end with a descriptor of its own (e.g. 16 for BRIEF-16); images are then refused.");
    v("reference_pixels", p.reference_pixels, Bounds::atLeast(0),
      "The extractor's num_features is meant for images of this many pixels (320 x 240); other sizes keep "
      "num_features x sqrt(pixels / reference_pixels), at most 4 x num_features: 1,386 of ORB's 800 on 640 x "
      "360, 1,600 on 640 x 480. On real 640 x 360 frames 800 features found a true candidate among the best "
      "three for 80 of 100 queries and 1,500 for 87 (docs/accuracy.md). 0 = num_features at any size.");
    v("max_pixels", p.max_pixels, Bounds::atLeast(kMinCappedPixels).orZero(),
      "Frames with more pixels are shrunk to at most this many before extraction (keypoints mapped back to the "
      "frame's pixels, the fit's inlier tolerances widened by the shrink), so that a large camera costs what this "
      "size costs; num_features then follows the shrunk size. 0 = every frame at its own size. "
      "config/real_cameras_budget.yaml uses 76,800 (320 x 240) with AKAZE at one sub-level per octave: on real "
      "640 x 360 frames the day accuracy of full-size AKAZE, and more at night than ORB's, at about ORB's cost "
      "(docs/accuracy.md).");
  }

  // An extractor's section, e.g. section<OrbParams>().num_features.
  template <class S>
  S& section() {
    return std::get<S>(extractors);
  }
  template <class S>
  const S& section() const {
    return std::get<S>(extractors);
  }

  int extractorBytes() const;   // the width `type` extracts
  int descriptorBytes() const;  // the database's width
  void validate() const;        // throws InvalidInput naming the first invalid field
};

// The extractor `params.type` names, with its section's parameters. Throws InvalidInput for an
// unknown type or invalid parameters.
std::unique_ptr<FeatureExtractor> makeFeatureExtractor(const FeatureParams& params);

}  // namespace mild
