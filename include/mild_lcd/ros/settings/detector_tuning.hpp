#pragma once

// Live tuning of the parameters that may change while running (the cfg generated from their
// runtime() declarations, tuning_cfg.hpp), in the private
// sub-namespace `tuning`, with dynamic_reconfigure's protocol (~tuning/set_parameters, the latched
// parameter_descriptions and parameter_updates; rqt_reconfigure and dynparam use it). The server is
// dynamic_reconfigure::Server's few steps, with the cfg's generated code doing the work, plus what
// that server cannot do: a request naming an unknown parameter or giving one a value of the wrong
// type is refused with a warning (dynamic_reconfigure's server skips such entries silently and
// applies the rest), and a value clamped to the cfg's bounds is said. It starts from the node's own
// values (YAML, rosparam), not the cfg's defaults; each change is validated at once and applied
// between two keyframes; a refused one is logged and undone. A request never waits for the detector
// (SharedDetector::requestRetune).

#include <mutex>
#include <string>

#include <dynamic_reconfigure/Reconfigure.h>
#include <ros/ros.h>

#include "mild_lcd/TuningConfig.h"
#include "mild_lcd/ros/detection/shared_detector.hpp"

namespace mild_lcd {

class DetectorTuning {
 public:
  DetectorTuning(const ros::NodeHandle& pnh, const std::string& log_name, SharedDetector& shared);

 private:
  bool set(dynamic_reconfigure::Reconfigure::Request& request, dynamic_reconfigure::Reconfigure::Response& response);
  // Validates `config` and hands it to the detector; on refusal sets it back to the values in force.
  void apply(mild_lcd::TuningConfig& config);
  void publish();  // config_ to the parameter server and parameter_updates

  std::string log_name_;
  SharedDetector& shared_;
  std::mutex mutex_;             // one request at a time
  mild::DetectorParams latest_;  // the latest values accepted (in force, or about to be)
  mild_lcd::TuningConfig config_;
  ros::NodeHandle nh_;
  ros::Publisher descriptions_, updates_;
  ros::ServiceServer set_service_;
};

}  // namespace mild_lcd
