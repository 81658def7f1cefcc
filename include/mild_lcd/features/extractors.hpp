#pragma once

// The feature extractors features/type can name: one entry each. An entry is a FeatureExtractor
// with kName, kDescriptorBytes (the width it extracts), Params (its parameter section, declared
// beside it: orb/, brisk/, akaze/) and a constructor (const Params&, double reference_pixels).
// Adding an extractor: its file, its entry here, CMake, its test.

#include "mild_lcd/common/registry.hpp"
#include "mild_lcd/features/akaze_extractor.hpp"
#include "mild_lcd/features/brisk_extractor.hpp"
#include "mild_lcd/features/orb_extractor.hpp"

namespace mild {

using FeatureExtractors = Registry<OrbExtractor, BriskExtractor, AkazeExtractor>;

}  // namespace mild
