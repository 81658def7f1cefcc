#pragma once

// The nodelet's services: sparse_match, save_database, load_database for one robot's map (in the
// robot's namespace when the node serves several), and reset of every map (in the node's namespace,
// advertised by the first robot's services). They are served by a thread and callback queue of
// their own, so that a long request never occupies the manager threads that deliver keyframes, and
// they hold the detector lock only to copy or swap state.

#include <memory>
#include <string>

#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include "mild_lcd/LoadDatabase.h"
#include "mild_lcd/SaveDatabase.h"
#include "mild_lcd/SparseMatch.h"
#include "mild_lcd/ros/detection/database_store.hpp"
#include "mild_lcd/ros/detection/keyframe_worker.hpp"
#include "mild_lcd/ros/detection/shared_detector.hpp"
#include "mild_lcd/ros/output/debug_image.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace mild_lcd {

class DetectorServices {
 public:
  // `robot_nh`: where the robot's services go; `reset_nh`: where reset goes (none: not here).
  DetectorServices(const ros::NodeHandle& robot_nh, const ros::NodeHandle* reset_nh, size_t robot,
                   const std::string& log_name, SharedDetector& shared, DatabaseStore& store, KeyframeWorker& worker,
                   DebugImageCache& debug_cache, size_t max_match_features);
  ~DetectorServices();
  void shutdown();

 private:
  bool sparseMatch(mild_lcd::SparseMatch::Request& request, mild_lcd::SparseMatch::Response& response);
  bool reset(std_srvs::Trigger::Request& request, std_srvs::Trigger::Response& response);
  bool save(mild_lcd::SaveDatabase::Request& request, mild_lcd::SaveDatabase::Response& response);
  bool load(mild_lcd::LoadDatabase::Request& request, mild_lcd::LoadDatabase::Response& response);

  mild::LoopDetector& detector() { return shared_.robot(robot_); }

  size_t robot_;
  std::string log_name_;
  SharedDetector& shared_;
  DatabaseStore& store_;
  KeyframeWorker& worker_;
  DebugImageCache& debug_cache_;
  const size_t max_match_features_;
  // The service thread's own verifier: it checks whatever it is asked, even with loop
  // verification off. Rebuilt after a retune of the detector (LoopDetector::retunes()).
  std::unique_ptr<mild::GeometricVerifier> verifier_;
  uint64_t verifier_retunes_ = 0;

  ros::CallbackQueue queue_;
  ros::NodeHandle nh_, reset_nh_;
  std::unique_ptr<ros::AsyncSpinner> spinner_;
  ros::ServiceServer match_srv_, reset_srv_, save_srv_, load_srv_;
};

}  // namespace mild_lcd
