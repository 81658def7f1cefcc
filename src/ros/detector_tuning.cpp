#include "detector_tuning.hpp"

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/params/parameters.hpp"
#include "mild_lcd/ros/tuning_config.hpp"

namespace mild_lcd {

DetectorTuning::DetectorTuning(const ros::NodeHandle& pnh, const std::string& log_name, SharedDetector& shared)
    : log_name_(log_name), shared_(shared) {
  // The server advertises set_parameters as it is constructed, with the cfg's defaults and no
  // callback yet: a request in that window would be answered and then lost. Holding the server's
  // own mutex until it holds the node's values and its callback makes such a request wait instead.
  boost::recursive_mutex::scoped_lock ready(mutex_);
  server_ =
      std::make_unique<dynamic_reconfigure::Server<mild_lcd::TuningConfig>>(mutex_, ros::NodeHandle(pnh, "tuning"));
  {
    const auto lock = shared_.lock();
    latest_ = shared_.team->params();
  }
  server_->updateConfig(tuningConfigOf(latest_));  // not the cfg's defaults
  server_->setCallback([this](mild_lcd::TuningConfig& config, uint32_t level) { apply(config, level); });
}

// Runs on the nodelet's callback queue, beside its diagnostics: it never waits for the detector,
// which a merge or a save may hold for seconds. The values are validated here, against the latest
// accepted ones, and applied by SharedDetector before the next keyframe.
void DetectorTuning::apply(mild_lcd::TuningConfig& config, uint32_t) {
  try {
    mild::DetectorParams next = paramsFromTuning(config, latest_);
    next.validate();
    if (mild::describeParameters(next) == mild::describeParameters(latest_)) return;
    shared_.requestRetune(next);
    latest_ = next;
    ROS_INFO_STREAM_NAMED(log_name_, "retuned: max_candidates " << next.candidates.max_candidates << ", exclusion "
                                                                << next.candidates.exclusion_frames
                                                                << " keyframes, decision probability "
                                                                << next.scoring.decision_probability << ", min_inliers "
                                                                << next.verification.min_inliers);
  } catch (const mild::InvalidInput& e) {
    ROS_WARN_STREAM_NAMED(log_name_, "dynamic_reconfigure change refused, values kept: " << e.what());
    config = tuningConfigOf(latest_);  // the server answers and publishes what holds
  }
}

}  // namespace mild_lcd
