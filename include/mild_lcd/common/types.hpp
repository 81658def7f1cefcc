#pragma once

#include <cstdint>
#include <limits>

namespace mild {

// Position of a keyframe in the database (0 = first inserted). 32-bit: no 65,535-keyframe cap.
using KeyframeIndex = uint32_t;
// Position of a feature among all stored features (keyframes' features are stored consecutively).
using FeatureId = uint32_t;

constexpr KeyframeIndex kAllKeyframes = std::numeric_limits<KeyframeIndex>::max();

}  // namespace mild
