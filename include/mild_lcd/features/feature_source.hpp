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
      "Feature extractor for image input, orb (256-bit descriptors), brisk (512) or akaze (486), whose descriptor "
      "width becomes the map's.");
    v("descriptor_bytes", p.descriptor_bytes, Bounds::in(kMinDescriptorBytes, kMaxDescriptorBytes).orZero(),
      "Width of the stored descriptors in bytes, 0 (the extractor's, or a Keyframe-only node's first keyframe's) "
      "or 8 to 64; another width serves a front-end's own Keyframe descriptors and refuses images.");
    v("reference_pixels", p.reference_pixels, Bounds::atLeast(0),
      "Image size in pixels (>= 0) that the extractors' num_features is meant for: other sizes scale it by "
      "sqrt(pixels / reference_pixels), at most 4 times, and 0 keeps it at any size.");
    v("max_pixels", p.max_pixels, Bounds::atLeast(kMinCappedPixels).orZero(),
      "Frames of more pixels than this are shrunk to it before extraction, keypoints mapped back to the frame's "
      "pixels (pixels, 0 = never, else >= 4096).");
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

// The setting that gives a detector `bytes`-wide descriptors: "features/type <name>" when an
// extractor extracts that width, else "features/descriptor_bytes <bytes>". Refusals of another
// width name it, so that the user knows what to set.
std::string descriptorSetting(int bytes);

// The extractor `params.type` names, with its section's parameters. Throws InvalidInput for an
// unknown type or invalid parameters.
std::unique_ptr<FeatureExtractor> makeFeatureExtractor(const FeatureParams& params);

}  // namespace mild
