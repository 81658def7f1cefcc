// mild_lcd/LoopClosureNodelet: keyframe images or features in, loop closures with probabilities
// out. Wiring only: settings, the worker, the services, diagnostics and the debug image each live
// in their own file; the algorithm lives in the core.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include <cv_bridge/cv_bridge.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <boost/make_shared.hpp>
#include <pluginlib/class_list_macros.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/io/database_directory.hpp"
#include "mild_lcd/ros/detection/database_store.hpp"
#include "mild_lcd/ros/detection/keyframe_worker.hpp"
#include "mild_lcd/ros/detection/periodic_task.hpp"
#include "mild_lcd/ros/input/input_admission.hpp"
#include "mild_lcd/ros/input/robot_inputs.hpp"
#include "mild_lcd/ros/messages/message_conversions.hpp"
#include "mild_lcd/ros/nodelets/sigterm_shutdown.hpp"
#include "mild_lcd/ros/output/debug_image.hpp"
#include "mild_lcd/ros/output/detector_diagnostics.hpp"
#include "mild_lcd/ros/services/detector_services.hpp"
#include "mild_lcd/ros/settings/detector_tuning.hpp"
#include "mild_lcd/ros/settings/node_settings.hpp"
#include "mild_lcd/ros/settings/ros_parameter_source.hpp"
#include "mild_lcd/ros/team/team_link.hpp"

namespace mild_lcd {
namespace {

// Where maps go by default: $ROS_HOME/mild_lcd, as ROS keeps its logs under $ROS_HOME.
std::string defaultDatabaseDir() {
  if (const char* ros_home = std::getenv("ROS_HOME"); ros_home && *ros_home) return std::string(ros_home) + "/mild_lcd";
  if (const char* home = std::getenv("HOME"); home && *home) return std::string(home) + "/.ros/mild_lcd";
  return "/tmp/mild_lcd";
}

// After ros::shutdown() rosconsole prints nothing; what a nodelet has to say while it is unloaded by a
// manager that is itself shutting down would be lost. Then it goes to stderr.
void shutdownMessage(const std::string& name, const std::string& text, bool warning) {
  if (ros::ok()) {
    if (warning) {
      ROS_WARN_STREAM_NAMED(name, text);
    } else {
      ROS_INFO_STREAM_NAMED(name, text);
    }
  } else {
    std::fprintf(stderr, "[%s] [%s]: %s\n", warning ? " WARN" : " INFO", name.c_str(), text.c_str());
  }
}

}  // namespace

class LoopClosureNodelet : public nodelet::Nodelet {
 public:
  ~LoopClosureNodelet() override {
    shutdown();
    sigterm_.reset();  // after the save: a SIGTERM meanwhile still means "shut down in order"
  }

 private:
  // What the node keeps per robot: its inputs, its output, its maps and their services. A node
  // serving one robot has one, in the node's own namespace.
  struct Robot {
    std::string name;
    ros::NodeHandle nh;
    std::unique_ptr<DatabaseStore> store;
    std::unique_ptr<RobotInputs> inputs;
    ros::Publisher loop_pub;
    std::unique_ptr<DetectorServices> services;
  };

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    configure(nh, pnh);
    team_names_ = settings_.robotNames();  // empty for a node serving one robot

    debug_cache_ = std::make_unique<DebugImageCache>(static_cast<size_t>(settings_.debug_image_cache),
                                                     static_cast<size_t>(settings_.debug_image_cache_mb) << 20);
    KeyframeWorker::Hooks hooks = workerHooks();
    if (!settings_.team_station.empty()) createTeamLink(nh, hooks);
    InputLimits limits;
    limits.max_image_pixels = static_cast<uint64_t>(settings_.max_image_pixels);
    limits.max_keyframe_features = static_cast<size_t>(settings_.max_keyframe_features);
    // A second thread gains only where there is a second core to run it.
    const bool extraction_thread = settings_.extraction_thread && std::thread::hardware_concurrency() > 1;
    worker_ = std::make_unique<KeyframeWorker>(shared_, static_cast<size_t>(settings_.queue_size),
                                               static_cast<size_t>(settings_.queue_mb) << 20, limits, std::move(hooks),
                                               extraction_thread);

    transport_ = std::make_unique<image_transport::ImageTransport>(nh);
    debug_pub_ = transport_->advertise("debug_image", 1);
    if (!team_names_.empty()) all_pub_ = nh.advertise<mild_lcd::LoopClosure>("loop_closures_all", 100);
    for (size_t r = 0; r < robots_.size(); ++r) {
      Robot& robot = *robots_[r];
      robot.loop_pub = robot.nh.advertise<mild_lcd::LoopClosure>("loop_closure", 100);
      robot.services = std::make_unique<DetectorServices>(robot.nh, r == 0 ? &nh : nullptr, r, getName(), shared_,
                                                          *robot.store, *worker_, *debug_cache_,
                                                          static_cast<size_t>(settings_.max_match_features));
    }
    diagnostics_ = std::make_unique<DetectorDiagnostics>(nh, pnh, getName(), shared_, *worker_);
    tuning_ = std::make_unique<DetectorTuning>(pnh, getName(), shared_);
    if (team_link_) diagnostics_->add("team", [this](auto& stat) { team_link_->diagnose(stat); });
    worker_->start();  // loads ~database_path first when ~load_on_start, then keyframes
    if (settings_.save_on_shutdown && settings_.autosave_period > 0) {
      autosave_ =
          std::make_unique<PeriodicTask>(std::chrono::seconds(settings_.autosave_period), [this] { autosave(); });
    }
    sigterm_ = std::make_unique<SigtermAsShutdown>();

    for (size_t r = 0; r < robots_.size(); ++r) {
      robots_[r]->inputs = std::make_unique<RobotInputs>(robots_[r]->nh, pnh, r, settings_, getName(),
                                                         [this](KeyframeInputPtr item) { enqueue(std::move(item)); });
    }
    logReady();
  }

  // Everything that can be wrong with the configuration is found before any ROS object exists:
  // a failed start leaves nothing half-built behind for the loader to tear down.
  void configure(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
    try {
      const RosParameterSource source(pnh);
      rejectUnknownParameters(source);
      settings_ = NodeSettings::load(source, defaultDatabaseDir());
      std::vector<std::string> names = settings_.robotNames();
      if (names.empty()) names.push_back("");  // one robot: topics and services without a prefix
      shared_.team = std::make_unique<mild::RobotTeam>(mild::loadDetectorParams(source), names);
      // Fed a front-end's own descriptors only, the maps take their width from the first keyframe
      // (unless features/descriptor_bytes fixes it): ORB-SLAM's ORB or OKVIS's BRISK need no setting.
      // A station's messages carry the width fixed at start-up, so a station keeps features/type's.
      shared_.team->takeWidthFromFirstKeyframe(!settings_.use_image_input && settings_.team_station.empty());
      shared_.failure.assign(names.size(), "");
      for (size_t r = 0; r < names.size(); ++r) {
        auto robot = std::make_unique<Robot>();
        robot->name = names[r];
        robot->nh = names[r].empty() ? nh : ros::NodeHandle(nh, names[r]);
        robot->store = std::make_unique<DatabaseStore>(settings_, r, names[r]);
        robots_.push_back(std::move(robot));
      }
      if (settings_.use_image_input) RobotInputs::checkTransport(nh, settings_);
    } catch (const std::exception& e) {
      NODELET_FATAL("not starting: %s", e.what());
      robots_.clear();
      shared_.team.reset();
      throw;  // the loader reports the failure; the manager and its other nodelets keep running
    }
  }

  // What the worker calls: at start-up, for each answer, to ask whether keypoints are wanted, to warn.
  KeyframeWorker::Hooks workerHooks() {
    KeyframeWorker::Hooks hooks;
    hooks.startup = [this] {
      // The team link starts on the maps just loaded, also when one robot's failed (the others'
      // keyframes go on); a link that cannot start (an unreadable ledger) stays off and never
      // writes over its ledger.
      const auto start_team = [this] {
        if (!team_link_) return;
        try {
          team_link_->start();
        } catch (const std::exception& e) {
          NODELET_FATAL("the team link (~team/station %s) is off: %s", settings_.team_station.c_str(), e.what());
        }
      };
      try {
        loadOnStart();
      } catch (...) {
        start_team();
        throw;
      }
      start_team();
    };
    hooks.publish = [this](const ProcessedKeyframe& k) { publish(k); };
    hooks.wants_keypoints = [this] { return debug_pub_.getNumSubscribers() > 0; };
    hooks.warn = [this](const std::string& what) { NODELET_WARN_THROTTLE(2.0, "%s", what.c_str()); };
    return hooks;
  }

  // With ~team/station: the link to the other stations, told of every keyframe stored and map replaced.
  void createTeamLink(ros::NodeHandle& nh, KeyframeWorker::Hooks& hooks) {
    // The ledger is saved with the maps, and read back only when they are.
    const std::string ledger =
        settings_.save_on_shutdown || settings_.load_on_start
            ? robots_.front()->store->directory() + "/" + settings_.team_station + mild::kTeamLedgerSuffix
            : "";
    // ~team/key_file: "" runs the team without a key (warned about); ~team/station_key_file and
    // ~team/roster_dir bind station names to keys of their own.
    TeamLink::KeyFiles keys;
    getPrivateNodeHandle().param<std::string>("team/key_file", keys.team, "");
    getPrivateNodeHandle().param<std::string>("team/station_key_file", keys.station, "");
    getPrivateNodeHandle().param<std::string>("team/roster_dir", keys.roster, "");
    team_link_ = std::make_unique<TeamLink>(
        nh, settings_, shared_, shared_.team->names(), ledger, keys,
        [this](const std::vector<size_t>& robots, const mild_lcd::LoopClosure::ConstPtr& msg) {
          for (size_t robot : robots) robots_.at(robot)->loop_pub.publish(msg);
          if (all_pub_) all_pub_.publish(msg);
        });
    shared_.on_map_replaced = [this](size_t robot) { team_link_->mapReplaced(robot); };
    hooks.stored = [this](const mild::DetectionResult& result) { team_link_->stored(result); };
  }

  void logReady() {
    // A copy, under the lock: the worker and the tuning server run already (a retune replaces them).
    mild::DetectorParams params;
    std::string width;
    {
      const auto lock = shared_.lock();
      params = shared_.team->params();
      const bool open = shared_.team->takesWidthFromFirstKeyframe() && params.features.descriptor_bytes == 0 &&
                        shared_.team->keyframes() == 0;
      width = open ? "descriptors as wide as the first keyframe's"
                   : std::to_string(shared_.team->descriptorBytes()) + "-byte descriptors";
    }
    NODELET_INFO(
        "mild_lcd ready: %s%s%s%s, %s features (%s%s), exclusion %d keyframes, "
        "verification %s, maps in %s",
        team_names_.empty() ? "" : ("robots " + settings_.robots + ", ").c_str(),
        settings_.use_image_input ? "image" : "",
        settings_.use_image_input && settings_.use_keyframe_input ? " and " : "",
        settings_.use_keyframe_input ? "keyframe input" : "", params.features.type.c_str(), width.c_str(),
        worker_->extractionThread() ? ", extracted on a thread of their own" : "", params.candidates.exclusion_frames,
        params.verification.enabled ? "on" : "off", robots_.front()->store->directory().c_str());
    const std::string cost = extractionCostWarning(settings_, params.features.type);
    if (!cost.empty()) NODELET_WARN("%s", cost.c_str());
  }

  // Callbacks only queue: the nodelet manager's threads are never held up by detection.
  void enqueue(KeyframeInputPtr item) {
    if (worker_->push(std::move(item)) == KeyframeWorker::Pushed::kDroppedOldest) {
      NODELET_WARN_THROTTLE(2.0,
                            "input queue full (queue_size %d, queue_mb %d): dropped the oldest keyframe, %zu dropped "
                            "so far",
                            settings_.queue_size, settings_.queue_mb, worker_->counters().dropped);
    }
  }

  void loadOnStart() {
    bool failed = false;
    for (const auto& robot : robots_) {
      try {
        const std::string message = robot->store->loadOnStart(shared_);
        if (!message.empty())
          NODELET_INFO("%s%s", robot->name.empty() ? "" : (robot->name + ": ").c_str(), message.c_str());
      } catch (const std::exception& e) {
        NODELET_FATAL(
            "cannot load the map %s at start-up: %s. The file is left as it is; that robot's keyframes are refused "
            "until a map is loaded with load_database. The file stays protected whatever is loaded meanwhile: no "
            "autosave, no save on shutdown, no save_database without a path writes over it; a save_database request "
            "naming it does (path: %s), as does loading it by hand",
            robot->store->databasePath().c_str(), e.what(), robot->store->databasePath().c_str());
        failed = true;
      }
    }
    if (failed) throw mild::IoError("a map failed to load at start-up");
  }

  // ~autosave_period: what SIGKILL, a crash or a power cut would lose is bounded by the period.
  void autosave() {
    for (const auto& robot : robots_) {
      try {
        const std::string message = robot->store->autosave(shared_);
        if (!message.empty()) NODELET_DEBUG("autosave: %s", message.c_str());
      } catch (const std::exception& e) {
        NODELET_WARN_THROTTLE(60.0, "autosave failed (the previous file is kept): %s", e.what());
      }
    }
    if (team_link_) {
      try {
        team_link_->save();
      } catch (const std::exception& e) {
        NODELET_WARN_THROTTLE(60.0, "could not save the station ledger: %s", e.what());
      }
    }
  }

  // Runs on the worker thread, without the detector lock.
  void publish(const ProcessedKeyframe& k) {
    const uint32_t robot = k.result.query_robot;
    // A shared pointer, never changed after publishing: a subscriber in the same manager (the
    // pose-graph nodelet) receives it without serialisation.
    const auto msg = boost::make_shared<mild_lcd::LoopClosure>(
        loopClosureToMsg(k.result, k.header, k.database_size, settings_.publish_correspondences, team_names_));
    if (!settings_.team_station.empty()) {  // a team across hosts: every side says whose it is
      msg->query_station = settings_.team_station;
      for (auto& c : msg->candidates) c.station = settings_.team_station;
    }
    robots_.at(robot)->loop_pub.publish(msg);
    if (all_pub_) all_pub_.publish(msg);
    if (!k.image.image.empty()) debug_cache_->remember(k.result.query_id, k.image.image, k.image.format, robot);
    if (debug_pub_.getNumSubscribers() == 0) return;
    const cv::Mat query = debug_cache_->find(k.result.query_id, robot);
    if (query.empty()) return;  // feature input: no pictures to draw
    const cv::Mat candidate = k.result.candidates.empty() ? cv::Mat()
                                                          : debug_cache_->find(k.result.candidates.front().id,
                                                                               k.result.candidates.front().robot);
    const cv::Mat canvas = drawDebugImage(query, k.query_keypoints, candidate, k.candidate_keypoints, k.result);
    debug_pub_.publish(cv_bridge::CvImage(k.header, sensor_msgs::image_encodings::BGR8, canvas).toImageMsg());
  }

  // Inputs first (nothing new arrives), then services, then the worker (what waits is discarded and
  // counted, the keyframe in progress finishes), then the maps are saved: roslaunch allows a node
  // 15 s after SIGINT, and a save of 5,000 keyframes takes well under one.
  void shutdown() {
    for (const auto& robot : robots_) {
      if (robot->inputs) robot->inputs->shutdown();
    }
    tuning_.reset();
    if (team_link_) team_link_->stop();  // no peer's work after this; what it had not taken is asked again
    for (const auto& robot : robots_) {
      if (robot->services) robot->services->shutdown();
    }
    autosave_.reset();  // waits for a save in progress; the last save follows
    if (worker_) {
      const size_t discarded = worker_->counters().discarded;
      worker_->stop();
      const size_t waiting = worker_->counters().discarded - discarded;  // the queue's and the one extracted
      if (waiting > 0) {
        shutdownMessage(getName(), "shutting down: " + std::to_string(waiting) + " queued keyframes were not processed",
                        true);
      }
    }
    if (shared_.team) {
      for (const auto& robot : robots_) {
        try {
          const std::string message = robot->store->saveOnShutdown(shared_);
          if (!message.empty()) shutdownMessage(getName(), message, robot->store->databaseProtected());
        } catch (const std::exception& e) {
          shutdownMessage(getName(), std::string("could not save the database on shutdown: ") + e.what(), true);
        }
      }
      if (team_link_ && settings_.save_on_shutdown) {
        try {
          team_link_->save();  // after the maps: it numbers their keyframes
        } catch (const std::exception& e) {
          shutdownMessage(getName(), std::string("could not save the station ledger: ") + e.what(), true);
        }
      }
    }
    diagnostics_.reset();
    for (const auto& robot : robots_) {
      robot->services.reset();
      robot->inputs.reset();
      robot->loop_pub.shutdown();
    }
    debug_pub_.shutdown();
    all_pub_.shutdown();
  }

  NodeSettings settings_;
  SharedDetector shared_;
  std::vector<std::unique_ptr<Robot>> robots_;
  std::vector<std::string> team_names_;  // for the messages; empty for one robot
  std::unique_ptr<DebugImageCache> debug_cache_;
  std::unique_ptr<KeyframeWorker> worker_;
  // Declared before the publisher that uses its plugins, so destroyed after it.
  std::unique_ptr<image_transport::ImageTransport> transport_;
  image_transport::Publisher debug_pub_;
  ros::Publisher all_pub_;
  std::unique_ptr<DetectorDiagnostics> diagnostics_;
  std::unique_ptr<DetectorTuning> tuning_;
  std::unique_ptr<PeriodicTask> autosave_;
  std::unique_ptr<SigtermAsShutdown> sigterm_;
  std::unique_ptr<TeamLink> team_link_;  // with ~team/station
};

}  // namespace mild_lcd

PLUGINLIB_EXPORT_CLASS(mild_lcd::LoopClosureNodelet, nodelet::Nodelet)
