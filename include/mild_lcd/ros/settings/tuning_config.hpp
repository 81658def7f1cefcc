#pragma once

// The bridge between dynamic_reconfigure's TuningConfig (generated from the declarations,
// tuning_cfg.hpp) and the detector's parameters: a TuningConfig field is a runtime parameter
// (runtimeParameterNames()) with its first '/' as '_'. Values travel typed, through the one
// parameter registry (detector/detector_parameters.hpp: visitParameters out, loadDetectorParams in,
// the request read as a ParameterSource), so names, types and validation are the detector's own
// and no value is written out as text and read back. No master needed: tested in test_ros_parts.

#include <string>

#include <dynamic_reconfigure/Config.h>

#include "mild_lcd/TuningConfig.h"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/ros/settings/tuning_cfg.hpp"

namespace mild_lcd {

// The entries of a dynamic_reconfigure request that name no tuning parameter, or give one a value
// of another type than the cfg's (dynamic_reconfigure's own parsing skips both without a word), as
// one line naming them; "" when there are none.
std::string unreadTuningEntries(const dynamic_reconfigure::Config& request);

// The detector's current values of its runtime parameters.
mild_lcd::TuningConfig tuningConfigOf(const mild::DetectorParams& params);
// `current` with the runtime parameters set from `config`. Throws mild::InvalidInput (naming the
// parameter) for a value the detector refuses.
mild::DetectorParams paramsFromTuning(const mild_lcd::TuningConfig& config, const mild::DetectorParams& current);

}  // namespace mild_lcd
