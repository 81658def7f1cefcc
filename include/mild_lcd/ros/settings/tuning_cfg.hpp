#pragma once

// What live tuning (dynamic_reconfigure) offers, derived from the parameter declarations: every
// parameter declared Bounds::runtime(), with its type, default, range and meaning. The build runs
// generate_tuning_cfg, which writes tuningCfgScript() to <build>/cfg/Tuning.cfg; dynamic_reconfigure
// turns that into mild_lcd/TuningConfig.h. Declaring a parameter runtime() is therefore all it takes
// to tune it live (test_retune checks that the detector applies it). Needs no ROS.

#include <string>

namespace mild_lcd {

// "detector/max_candidates" <-> "detector_max_candidates" (dynamic_reconfigure names have no '/').
std::string tuningName(const std::string& parameter);
// Throws mild::InvalidInput when no runtime parameter has that tuning name.
std::string parameterName(const std::string& tuning_name);

// The dynamic_reconfigure cfg (a Python script for its ParameterGenerator) of the runtime
// parameters. Throws mild::InvalidInput for a runtime parameter of a type it cannot offer.
std::string tuningCfgScript();

}  // namespace mild_lcd
