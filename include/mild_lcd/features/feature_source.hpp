#pragma once

#include <memory>
#include <string>
#include <vector>

#include "mild_lcd/features/akaze_extractor.hpp"
#include "mild_lcd/features/brisk_extractor.hpp"
#include "mild_lcd/features/feature_extractor.hpp"
#include "mild_lcd/features/orb_extractor.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

// The names features/type accepts.
const std::vector<std::string>& featureTypes();

// The feature source of a detector: `type` names the extractor (features/type), whose own
// parameters sit in its section (orb/, brisk/, akaze/).
struct FeatureParams {
  std::string type = "orb";
  int descriptor_bytes = 0;
  double reference_pixels = 76800.0;
  OrbParams orb;
  BriskParams brisk;
  AkazeParams akaze;

  static constexpr const char* kSection = "features";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("type", p.type, Bounds::oneOf(featureTypes()),
      "The feature extractor for image input: orb (256-bit descriptors), brisk (512), akaze (486 bits in 61 "
      "bytes). Its descriptor width becomes the database's, and the saved map's: a map is loaded only by a "
      "detector of the same width.");
    v("descriptor_bytes", p.descriptor_bytes, Bounds::in(kMinDescriptorBytes, kMaxDescriptorBytes).orZero(),
      "Width of the stored descriptors in bytes; 0 = the extractor's (ORB 32, BRISK 64, AKAZE 61). Another "
      "value serves Keyframe input from a front-end with a descriptor of its own (e.g. 16 for BRIEF-16); images "
      "are then refused.");
    v("reference_pixels", p.reference_pixels, Bounds::atLeast(0),
      "The extractor's num_features is meant for images of this many pixels (320 x 240); other sizes keep "
      "num_features x sqrt(pixels / reference_pixels), at most 4 x num_features: 1,386 of ORB's 800 on 640 x "
      "360, 1,600 on 640 x 480. On real 640 x 360 frames 800 features found a true candidate among the best "
      "three for 80 of 100 queries and 1,500 for 87 (docs/accuracy.md). 0 = num_features at any size.");
  }

  int extractorBytes() const;   // the width `type` extracts
  int descriptorBytes() const;  // the database's width
  void validate() const;        // throws InvalidInput naming the first invalid field
};

// The extractor `params.type` names, with its section's parameters. Throws InvalidInput for an
// unknown type or invalid parameters.
std::unique_ptr<FeatureExtractor> makeFeatureExtractor(const FeatureParams& params);

}  // namespace mild
