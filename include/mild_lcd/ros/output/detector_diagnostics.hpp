#pragma once

// The nodelet's diagnostics (diagnostic_updater): database size and memory, queue, dropped /
// rejected / discarded keyframes, timings, and an ERROR while a start-up load failure stands.

#include <functional>
#include <memory>
#include <string>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include "mild_lcd/ros/detection/keyframe_worker.hpp"
#include "mild_lcd/ros/detection/shared_detector.hpp"

namespace mild_lcd {

class DetectorDiagnostics {
 public:
  DetectorDiagnostics(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name, SharedDetector& shared,
                      KeyframeWorker& worker);
  // Another status the node reports beside the detector's (the team link's, per peer).
  void add(const std::string& name, std::function<void(diagnostic_updater::DiagnosticStatusWrapper&)> task);

 private:
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  SharedDetector& shared_;
  KeyframeWorker& worker_;
  std::unique_ptr<diagnostic_updater::Updater> updater_;
  ros::WallTimer timer_;
  size_t reported_dropped_ = 0, reported_rejected_ = 0;
  std::string failure_;
  size_t robots_ = 1;
};

}  // namespace mild_lcd
