#include "mild_lcd/ros/settings/detector_tuning.hpp"

#include <dynamic_reconfigure/ConfigDescription.h>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/ros/settings/tuning_config.hpp"

namespace mild_lcd {

DetectorTuning::DetectorTuning(const ros::NodeHandle& pnh, const std::string& log_name, SharedDetector& shared)
    : log_name_(log_name), shared_(shared), nh_(pnh, "tuning") {
  {
    const auto lock = shared_.lock();
    latest_ = shared_.team->params();
  }
  config_ = tuningConfigOf(latest_);  // not the cfg's defaults
  descriptions_ = nh_.advertise<dynamic_reconfigure::ConfigDescription>("parameter_descriptions", 1, true);
  descriptions_.publish(mild_lcd::TuningConfig::__getDescriptionMessage__());  // with bounds and defaults
  updates_ = nh_.advertise<dynamic_reconfigure::Config>("parameter_updates", 1, true);
  publish();
  // Last: a request can only come once the node's values are in place.
  set_service_ = nh_.advertiseService("set_parameters", &DetectorTuning::set, this);
}

bool DetectorTuning::set(dynamic_reconfigure::Reconfigure::Request& request,
                         dynamic_reconfigure::Reconfigure::Response& response) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::string unread = unreadTuningEntries(request.config);
  if (!unread.empty()) {
    ROS_WARN_STREAM_NAMED(log_name_, "dynamic_reconfigure request refused, values kept: " << unread);
  } else {
    mild_lcd::TuningConfig next = config_;
    next.__fromMessage__(request.config);
    dynamic_reconfigure::Config asked, clamped;
    next.__toMessage__(asked);
    next.__clamp__();
    next.__toMessage__(clamped);
    if (!(asked == clamped)) {
      ROS_WARN_STREAM_NAMED(log_name_, "dynamic_reconfigure: values outside the cfg's bounds were clamped to them");
    }
    apply(next);
    config_ = next;
  }
  publish();
  config_.__toMessage__(response.config);
  return true;
}

// Runs on the nodelet's callback queue, beside its diagnostics: it never waits for the detector,
// which a merge or a save may hold for seconds. The values are validated here, against the latest
// accepted ones, and applied by SharedDetector before the next keyframe.
void DetectorTuning::apply(mild_lcd::TuningConfig& config) {
  try {
    mild::DetectorParams next = paramsFromTuning(config, latest_);
    next.validate();
    const auto before = mild::describeParameters(latest_), after = mild::describeParameters(next);
    std::string changes;  // whatever changed, named from the registry
    for (size_t i = 0; i < after.size(); ++i) {
      if (before[i].second != after[i].second)
        changes += (changes.empty() ? "" : ", ") + after[i].first + " " + after[i].second;
    }
    if (changes.empty()) return;
    shared_.requestRetune(next);
    latest_ = next;
    ROS_INFO_STREAM_NAMED(log_name_, "retuned: " << changes);
  } catch (const mild::InvalidInput& e) {
    ROS_WARN_STREAM_NAMED(log_name_, "dynamic_reconfigure change refused, values kept: " << e.what());
    config = tuningConfigOf(latest_);  // the answer and parameter_updates carry what holds
  }
}

void DetectorTuning::publish() {
  config_.__toServer__(nh_);
  dynamic_reconfigure::Config msg;
  config_.__toMessage__(msg);
  updates_.publish(msg);
}

}  // namespace mild_lcd
