#pragma once

// dynamic_reconfigure for the parameters that may change while running (cfg/Tuning.cfg), served in
// the private sub-namespace `tuning` (~tuning/set_parameters; rqt_reconfigure lists it). The server
// starts from the node's own values (YAML, rosparam), not the cfg's defaults; each change is
// applied between two keyframes, a refused one is logged and undone. A request never waits for
// the detector (SharedDetector::requestRetune).

#include <memory>
#include <string>

#include <dynamic_reconfigure/server.h>
#include <ros/ros.h>
#include <boost/thread/recursive_mutex.hpp>

#include "mild_lcd/TuningConfig.h"
#include "mild_lcd/ros/shared_detector.hpp"

namespace mild_lcd {

class DetectorTuning {
 public:
  DetectorTuning(const ros::NodeHandle& pnh, const std::string& log_name, SharedDetector& shared);

 private:
  void apply(mild_lcd::TuningConfig& config, uint32_t level);

  std::string log_name_;
  SharedDetector& shared_;
  mild::DetectorParams latest_;   // the latest values accepted (in force, or about to be)
  boost::recursive_mutex mutex_;  // the server's: held by every request while it is applied
  std::unique_ptr<dynamic_reconfigure::Server<mild_lcd::TuningConfig>> server_;
};

}  // namespace mild_lcd
