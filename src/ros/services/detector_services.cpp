#include "mild_lcd/ros/services/detector_services.hpp"

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/ros/services/sparse_match_service.hpp"

namespace mild_lcd {
namespace {

mild::VerificationParams alwaysOn(mild::VerificationParams p) {
  p.enabled = true;
  return p;
}

}  // namespace

DetectorServices::DetectorServices(const ros::NodeHandle& robot_nh, const ros::NodeHandle* reset_nh, size_t robot,
                                   const std::string& log_name, SharedDetector& shared, DatabaseStore& store,
                                   KeyframeWorker& worker, DebugImageCache& debug_cache, size_t max_match_features)
    : robot_(robot),
      log_name_(log_name),
      shared_(shared),
      store_(store),
      worker_(worker),
      debug_cache_(debug_cache),
      max_match_features_(max_match_features),
      verifier_(std::make_unique<mild::GeometricVerifier>(alwaysOn(shared.team->params().verification))),
      nh_(robot_nh) {
  nh_.setCallbackQueue(&queue_);
  match_srv_ = nh_.advertiseService("sparse_match", &DetectorServices::sparseMatch, this);
  if (reset_nh) {
    reset_nh_ = *reset_nh;
    reset_nh_.setCallbackQueue(&queue_);
    reset_srv_ = reset_nh_.advertiseService("reset", &DetectorServices::reset, this);
  }
  save_srv_ = nh_.advertiseService("save_database", &DetectorServices::save, this);
  load_srv_ = nh_.advertiseService("load_database", &DetectorServices::load, this);
  spinner_ = std::make_unique<ros::AsyncSpinner>(1, &queue_);
  spinner_->start();
}

DetectorServices::~DetectorServices() { shutdown(); }

void DetectorServices::shutdown() {
  match_srv_.shutdown();
  reset_srv_.shutdown();
  save_srv_.shutdown();
  load_srv_.shutdown();
  if (spinner_) spinner_->stop();
  spinner_.reset();
}

bool DetectorServices::sparseMatch(mild_lcd::SparseMatch::Request& request, mild_lcd::SparseMatch::Response& response) {
  const auto stored = [this](uint64_t id) -> std::optional<mild::Features> {
    const auto lock = shared_.lock();  // a copy, then the lock is free again
    auto k = detector().map().find(id);
    if (!k) return std::nullopt;
    return detector().map().features(*k);
  };
  {
    // The verification parameters may have been retuned (dynamic_reconfigure) since it was built.
    const auto lock = shared_.lock();
    if (shared_.team->retunes() != verifier_retunes_) {
      verifier_ = std::make_unique<mild::GeometricVerifier>(alwaysOn(shared_.team->params().verification));
      verifier_retunes_ = shared_.team->retunes();
    }
  }
  response = mild_lcd::sparseMatch(request, stored, *verifier_, max_match_features_);
  if (!response.success) ROS_WARN_STREAM_THROTTLE_NAMED(2.0, log_name_, "sparse_match: " << response.message);
  return true;  // failures are reported in the response, not as a failed call
}

bool DetectorServices::reset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
  const size_t pending = worker_.discardPending();
  const auto lock = shared_.lock();
  const size_t keyframes = shared_.team->keyframes();
  shared_.resetMaps();
  for (std::string& f : shared_.failure) f.clear();
  debug_cache_.clear();
  worker_.refreshSnapshot(*shared_.team);
  response.success = true;
  response.message = "cleared " + std::to_string(keyframes) + " keyframes and " + std::to_string(pending) +
                     " waiting in the queue (counted as discarded)";
  ROS_INFO_STREAM_NAMED(log_name_, "reset: " << response.message);
  return true;
}

bool DetectorServices::save(mild_lcd::SaveDatabase::Request& request, mild_lcd::SaveDatabase::Response& response) {
  try {
    response.message = store_.save(shared_, request.path);
    response.success = true;
    ROS_INFO_STREAM_NAMED(log_name_, response.message);
  } catch (const std::exception& e) {
    response.success = false;
    response.message = e.what();
    ROS_WARN_STREAM_NAMED(log_name_, "save_database: " << e.what());
  }
  return true;
}

bool DetectorServices::load(mild_lcd::LoadDatabase::Request& request, mild_lcd::LoadDatabase::Response& response) {
  try {
    if (request.merge && request.continue_session) {
      throw mild::InvalidInput("merge and continue_session exclude each other: a merged map joins as earlier sessions");
    }
    if (request.merge) {
      response.message = store_.merge(shared_, request.path).message;  // ids stay: the debug cache too
    } else {
      response.message = store_.load(shared_, request.path, request.continue_session).message;
      debug_cache_.clear(static_cast<uint32_t>(robot_));
    }
    response.success = true;
    ROS_INFO_STREAM_NAMED(log_name_, response.message);
  } catch (const std::exception& e) {  // std::bad_alloc included: the database is as it was
    response.success = false;
    response.message = e.what();
    ROS_WARN_STREAM_NAMED(log_name_, "load_database: " << e.what());
  }
  const auto lock = shared_.lock();
  response.keyframes = static_cast<uint32_t>(detector().map().size());
  worker_.refreshSnapshot(*shared_.team);
  return true;
}

}  // namespace mild_lcd
