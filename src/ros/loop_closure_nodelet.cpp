// mild_lcd/LoopClosureNodelet: keyframe images or features in, loop closures with probabilities
// out. Wiring only: settings, the worker, the services, diagnostics and the debug image each live
// in their own file; the algorithm lives in the core.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <string>

#include <cv_bridge/cv_bridge.h>
#include <image_transport/camera_common.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <pluginlib/class_list_macros.hpp>

#include "detector_diagnostics.hpp"
#include "detector_services.hpp"
#include "detector_tuning.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/ros/conversions.hpp"
#include "mild_lcd/ros/database_store.hpp"
#include "mild_lcd/ros/debug_image.hpp"
#include "mild_lcd/ros/keyframe_worker.hpp"
#include "mild_lcd/ros/node_settings.hpp"
#include "mild_lcd/ros/ros_parameter_source.hpp"

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
  ~LoopClosureNodelet() override { shutdown(); }

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    // Everything that can be wrong with the configuration is found before any ROS object exists:
    // a failed start leaves nothing half-built behind for the loader to tear down.
    std::unique_ptr<DatabaseStore> store;
    try {
      const RosParameterSource source(pnh);
      rejectUnknownParameters(source);
      settings_ = NodeSettings::load(source, defaultDatabaseDir());
      shared_.detector = std::make_unique<mild::LoopDetector>(mild::loadDetectorParams(source));
      store = std::make_unique<DatabaseStore>(settings_);
      if (settings_.use_image_input) checkTransport(nh);
    } catch (const std::exception& e) {
      NODELET_FATAL("not starting: %s", e.what());
      throw;  // the loader reports the failure; the manager and its other nodelets keep running
    }
    store_ = std::move(store);

    debug_cache_ = std::make_unique<DebugImageCache>(static_cast<size_t>(settings_.debug_image_cache),
                                                     static_cast<size_t>(settings_.debug_image_cache_mb) << 20);
    KeyframeWorker::Hooks hooks;
    hooks.startup = [this] { loadOnStart(); };
    hooks.publish = [this](const ProcessedKeyframe& k) { publish(k); };
    hooks.wants_keypoints = [this] { return debug_pub_.getNumSubscribers() > 0; };
    hooks.warn = [this](const std::string& what) { NODELET_WARN_THROTTLE(2.0, "%s", what.c_str()); };
    worker_ = std::make_unique<KeyframeWorker>(shared_, static_cast<size_t>(settings_.queue_size),
                                               static_cast<uint64_t>(settings_.max_image_pixels), std::move(hooks));

    loop_pub_ = nh.advertise<mild_lcd::LoopClosure>("loop_closure", 100);
    transport_ = std::make_unique<image_transport::ImageTransport>(nh);
    debug_pub_ = transport_->advertise("debug_image", 1);
    services_ = std::make_unique<DetectorServices>(nh, getName(), shared_, *store_, *worker_, *debug_cache_,
                                                   static_cast<size_t>(settings_.max_match_features));
    diagnostics_ = std::make_unique<DetectorDiagnostics>(nh, pnh, getName(), shared_, *worker_);
    tuning_ = std::make_unique<DetectorTuning>(pnh, getName(), shared_);
    worker_->start();  // loads ~database_path first when ~load_on_start, then keyframes

    if (settings_.use_image_input && settings_.use_camera_info) subscribeCameraInfo(nh);
    if (settings_.use_image_input) subscribeImages(nh, pnh);
    if (settings_.use_keyframe_input) {
      keyframe_sub_ = nh.subscribe<mild_lcd::Keyframe>("keyframe", settings_.queue_size,
                                                       [this](const mild_lcd::KeyframeConstPtr& m) {
                                                         enqueue({nullptr, nullptr, m, {}});
                                                       });
    }
    const mild::DetectorParams& params = shared_.detector->params();
    NODELET_INFO("mild_lcd ready: %s%s%s, %d hash tables, exclusion %d keyframes, verification %s, maps in %s",
                 settings_.use_image_input ? "image" : "",
                 settings_.use_image_input && settings_.use_keyframe_input ? " and " : "",
                 settings_.use_keyframe_input ? "keyframe input" : "", params.database.index.num_tables,
                 params.candidates.exclusion_frames, params.verification.enabled ? "on" : "off",
                 store_->directory().c_str());
  }

  // image_transport's `compressed` plugin is not packaged for Debian's ROS; without it the
  // compressed topic is subscribed and decoded here, so `~image_transport: compressed` works either
  // way. Any other name must be an installed plugin.
  bool decodesCompressedItself(ros::NodeHandle& nh) const {
    if (settings_.image_transport != "compressed") return false;
    const auto loadable = image_transport::ImageTransport(nh).getLoadableTransports();
    return std::find(loadable.begin(), loadable.end(), "image_transport/compressed") == loadable.end();
  }

  void checkTransport(ros::NodeHandle& nh) const {
    if (decodesCompressedItself(nh)) return;
    const auto loadable = image_transport::ImageTransport(nh).getLoadableTransports();
    if (std::find(loadable.begin(), loadable.end(), "image_transport/" + settings_.image_transport) != loadable.end())
      return;
    std::string names;
    for (const auto& t : loadable) names += (names.empty() ? "" : ", ") + t.substr(t.find('/') + 1);
    throw mild::InvalidInput("parameter ~image_transport: no transport plugin '" + settings_.image_transport +
                             "' is installed (installed: " + names + (names.empty() ? "" : ", ") +
                             "and compressed, which mild_lcd decodes itself)");
  }

  void subscribeImages(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
    if (decodesCompressedItself(nh)) {
      const std::string topic = nh.resolveName("image") + "/compressed";
      compressed_sub_ = nh.subscribe<sensor_msgs::CompressedImage>(
          topic, settings_.queue_size, [this](const sensor_msgs::CompressedImageConstPtr& m) {
            enqueue({nullptr, m, nullptr, latestCamera()});
          });
      NODELET_INFO("subscribed to %s (compressed images, decoded by mild_lcd)", topic.c_str());
      return;
    }
    image_sub_ = transport_->subscribe(
        "image", settings_.queue_size,
        [this](const sensor_msgs::ImageConstPtr& m) {
          enqueue({m, nullptr, nullptr, latestCamera()});
        },
        ros::VoidPtr(), image_transport::TransportHints(settings_.image_transport, ros::TransportHints(), pnh));
    NODELET_INFO("subscribed to %s (transport %s)", image_sub_.getTopic().c_str(), settings_.image_transport.c_str());
  }

  // camera_info beside `image` (image_transport's naming). Not a synchronised camera subscriber: an
  // image whose camera_info never comes (many bags and drivers lack one) must still be processed,
  // and intrinsics rarely change, so each image takes the newest intrinsics received before it.
  void subscribeCameraInfo(ros::NodeHandle& nh) {
    const std::string topic = image_transport::getCameraInfoTopic(nh.resolveName("image"));
    camera_info_sub_ =
        nh.subscribe<sensor_msgs::CameraInfo>(topic, 1, [this](const sensor_msgs::CameraInfoConstPtr& m) {
          try {
            const mild::CameraIntrinsics camera = intrinsicsFromMsg(*m);
            std::lock_guard<std::mutex> lock(camera_mutex_);
            if (camera != camera_ && camera.known()) {
              NODELET_INFO("camera intrinsics from %s: fx %.2f fy %.2f cx %.2f cy %.2f",
                           camera_info_sub_.getTopic().c_str(), camera.fx, camera.fy, camera.cx, camera.cy);
            }
            camera_ = camera;
          } catch (const mild::InvalidInput& e) {
            NODELET_WARN_THROTTLE(10.0, "ignored camera_info: %s", e.what());
          }
        });
    NODELET_INFO("subscribed to %s (intrinsics for verified loops' relative pose)", topic.c_str());
  }

  mild::CameraIntrinsics latestCamera() {
    std::lock_guard<std::mutex> lock(camera_mutex_);
    return camera_;
  }

  // Callbacks only queue: the nodelet manager's threads are never held up by detection.
  void enqueue(KeyframeInput item) {
    if (!worker_->push(std::move(item))) {
      NODELET_WARN_THROTTLE(2.0, "input queue full (queue_size %d): dropped the oldest keyframe, %zu dropped so far",
                            settings_.queue_size, worker_->counters().dropped);
    }
  }

  void loadOnStart() {
    try {
      const std::string message = store_->loadOnStart(shared_);
      if (!message.empty()) NODELET_INFO("%s", message.c_str());
    } catch (const std::exception& e) {
      NODELET_FATAL(
          "cannot load the map at start-up: %s. The file is left as it is; keyframes are refused and nothing "
          "is saved until a map is loaded with load_database (or the node restarts)",
          e.what());
      throw;
    }
  }

  // Runs on the worker thread, without the detector lock.
  void publish(const ProcessedKeyframe& k) {
    loop_pub_.publish(loopClosureToMsg(k.result, k.header, k.database_size, settings_.publish_correspondences));
    if (!k.image.image.empty()) debug_cache_->remember(k.result.query_id, k.image.image, k.image.format);
    if (debug_pub_.getNumSubscribers() == 0) return;
    const cv::Mat query = debug_cache_->find(k.result.query_id);
    if (query.empty()) return;  // feature input: no pictures to draw
    const cv::Mat candidate =
        k.result.candidates.empty() ? cv::Mat() : debug_cache_->find(k.result.candidates.front().id);
    const cv::Mat canvas = drawDebugImage(query, k.query_keypoints, candidate, k.candidate_keypoints, k.result);
    debug_pub_.publish(cv_bridge::CvImage(k.header, sensor_msgs::image_encodings::BGR8, canvas).toImageMsg());
  }

  // Inputs first (nothing new arrives), then services, then the worker (what waits is discarded and
  // counted, the keyframe in progress finishes), then the map is saved: roslaunch allows a node
  // 15 s after SIGINT, and a save of 5,000 keyframes takes well under one.
  void shutdown() {
    image_sub_.shutdown();
    camera_info_sub_.shutdown();
    compressed_sub_.shutdown();
    keyframe_sub_.shutdown();
    tuning_.reset();
    if (services_) services_->shutdown();
    if (worker_) {
      const size_t waiting = worker_->counters().queued;
      worker_->stop();
      if (waiting > 0) {
        shutdownMessage(getName(), "shutting down: " + std::to_string(waiting) + " queued keyframes were not processed",
                        true);
      }
    }
    if (store_ && shared_.detector) {
      try {
        const std::string message = store_->saveOnShutdown(shared_);
        if (!message.empty()) shutdownMessage(getName(), message, !store_->savesAllowed());
      } catch (const std::exception& e) {
        shutdownMessage(getName(), std::string("could not save the database on shutdown: ") + e.what(), true);
      }
    }
    diagnostics_.reset();
    services_.reset();
    debug_pub_.shutdown();
    loop_pub_.shutdown();
  }

  NodeSettings settings_;
  SharedDetector shared_;
  std::unique_ptr<DatabaseStore> store_;
  std::unique_ptr<DebugImageCache> debug_cache_;
  std::unique_ptr<KeyframeWorker> worker_;
  // Declared before the publishers and subscribers that use its plugins, so destroyed after them.
  std::unique_ptr<image_transport::ImageTransport> transport_;
  image_transport::Subscriber image_sub_;
  ros::Subscriber compressed_sub_, keyframe_sub_, camera_info_sub_;
  std::mutex camera_mutex_;
  mild::CameraIntrinsics camera_;  // newest from camera_info
  ros::Publisher loop_pub_;
  image_transport::Publisher debug_pub_;
  std::unique_ptr<DetectorServices> services_;
  std::unique_ptr<DetectorDiagnostics> diagnostics_;
  std::unique_ptr<DetectorTuning> tuning_;
};

}  // namespace mild_lcd

PLUGINLIB_EXPORT_CLASS(mild_lcd::LoopClosureNodelet, nodelet::Nodelet)
