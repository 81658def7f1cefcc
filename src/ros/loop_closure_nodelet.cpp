// mild_lcd/LoopClosureNodelet: keyframe images or features in, loop closures with probabilities
// out. It converts messages and calls mild::LoopDetector; the algorithm lives in the core.

#include <malloc.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <unordered_map>

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_updater/diagnostic_updater.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <std_srvs/Trigger.h>

#include "mild_lcd/LoadDatabase.h"
#include "mild_lcd/SaveDatabase.h"
#include "mild_lcd/bounded_queue.hpp"
#include "mild_lcd/database_file.hpp"
#include "mild_lcd/errors.hpp"
#include "mild_lcd/loop_detector.hpp"
#include "mild_lcd/ros/conversions.hpp"
#include "mild_lcd/ros/ros_parameter_source.hpp"

namespace mild_lcd {

// Settings of the ROS wrapper itself (the detector's are under orb/, index/, ... as in
// config/default.yaml).
struct NodeletSettings {
  bool use_image_input = true;
  bool use_keyframe_input = true;
  int queue_size = 100;
  int debug_image_cache = 1000;
  std::string database_path;
  bool load_on_start = false;
  bool save_on_shutdown = false;

  static NodeletSettings load(const ros::NodeHandle& pnh) {
    NodeletSettings s;
    pnh.param("use_image_input", s.use_image_input, s.use_image_input);
    pnh.param("use_keyframe_input", s.use_keyframe_input, s.use_keyframe_input);
    pnh.param("queue_size", s.queue_size, s.queue_size);
    pnh.param("debug_image_cache", s.debug_image_cache, s.debug_image_cache);
    pnh.param("database_path", s.database_path, s.database_path);
    pnh.param("load_on_start", s.load_on_start, s.load_on_start);
    pnh.param("save_on_shutdown", s.save_on_shutdown, s.save_on_shutdown);
    if ((s.load_on_start || s.save_on_shutdown) && s.database_path.empty()) {
      throw mild::InvalidInput("load_on_start and save_on_shutdown need database_path (the database file)");
    }
    if (!s.use_image_input && !s.use_keyframe_input) {
      throw mild::InvalidInput("use_image_input and use_keyframe_input are both false: nothing to listen to");
    }
    if (s.queue_size < 1) throw mild::InvalidInput("queue_size must be >= 1, got " + std::to_string(s.queue_size));
    if (s.debug_image_cache < 0) throw mild::InvalidInput("debug_image_cache must be >= 0");
    return s;
  }
};

class LoopClosureNodelet : public nodelet::Nodelet {
 public:
  ~LoopClosureNodelet() override {
    if (queue_) queue_->close();
    if (worker_.joinable()) worker_.join();
    if (detector_ && settings_.save_on_shutdown) {
      try {
        mild::saveDetector(*detector_, settings_.database_path);
        NODELET_INFO("saved %zu keyframes to %s", detector_->size(), settings_.database_path.c_str());
      } catch (const mild::InvalidInput& e) {
        NODELET_ERROR("could not save the database on shutdown: %s", e.what());
      }
    }
  }

 private:
  // One keyframe as it arrived; exactly one pointer is set.
  struct Input {
    sensor_msgs::ImageConstPtr image;
    sensor_msgs::CompressedImageConstPtr compressed;
    mild_lcd::KeyframeConstPtr keyframe;
  };

  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      settings_ = NodeletSettings::load(pnh);
      detector_ = std::make_unique<mild::LoopDetector>(mild::loadDetectorParams(RosParameterSource(pnh)));
    } catch (const mild::InvalidInput& e) {
      NODELET_FATAL("invalid parameter: %s", e.what());
      throw;  // the loader reports the failure; nothing half-configured keeps running
    }
    if (settings_.load_on_start) {
      if (!std::filesystem::exists(settings_.database_path)) {
        NODELET_WARN("database %s does not exist yet: starting with an empty map", settings_.database_path.c_str());
      } else {
        try {  // a map from an earlier run: a new session on it
          NODELET_INFO("%s", mild::loadDetector(*detector_, settings_.database_path, false).message.c_str());
        } catch (const mild::InvalidInput& e) {
          // Starting empty would overwrite the file on shutdown: refuse, so that it can be looked at.
          NODELET_FATAL("cannot load the database at start-up: %s", e.what());
          detector_.reset();  // nothing for save_on_shutdown to write over it
          throw;
        }
      }
    }
    const mild::DetectorParams& params = detector_->params();
    match_verifier_ = std::make_unique<mild::GeometricVerifier>(serviceVerificationParams(params.verification));

    queue_ = std::make_unique<mild::BoundedQueue<Input>>(static_cast<size_t>(settings_.queue_size));
    worker_ = std::thread([this] { workerLoop(); });

    loop_pub_ = nh.advertise<mild_lcd::LoopClosure>("loop_closure", 100);
    image_transport::ImageTransport it(nh);
    debug_pub_ = it.advertise("debug_image", 1);

    if (settings_.use_image_input) subscribeImages(nh, pnh);
    if (settings_.use_keyframe_input) {
      keyframe_sub_ = nh.subscribe<mild_lcd::Keyframe>("keyframe", settings_.queue_size,
                                                       [this](const mild_lcd::KeyframeConstPtr& m) { enqueue({nullptr, nullptr, m}); });
    }
    match_srv_ = nh.advertiseService("sparse_match", &LoopClosureNodelet::sparseMatchService, this);
    reset_srv_ = nh.advertiseService("reset", &LoopClosureNodelet::resetService, this);
    save_srv_ = nh.advertiseService("save_database", &LoopClosureNodelet::saveService, this);
    load_srv_ = nh.advertiseService("load_database", &LoopClosureNodelet::loadService, this);

    updater_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
    updater_->setHardwareID("mild_lcd");
    updater_->add("loop closure detector", this, &LoopClosureNodelet::diagnose);
    diagnostics_timer_ = nh.createWallTimer(ros::WallDuration(0.5), [this](const ros::WallTimerEvent&) { updater_->update(); });

    NODELET_INFO("mild_lcd ready: %s%s%s, %d hash tables, exclusion %d keyframes, verification %s",
                 settings_.use_image_input ? "image" : "", settings_.use_image_input && settings_.use_keyframe_input ? " and " : "",
                 settings_.use_keyframe_input ? "keyframe input" : "", params.database.index.num_tables,
                 params.candidates.exclusion_frames, params.verification.enabled ? "on" : "off");
  }

  // The sparse_match service verifies whatever it is asked, even when loop verification is off.
  static mild::VerificationParams serviceVerificationParams(mild::VerificationParams p) {
    p.enabled = true;
    return p;
  }

  // image_transport's `compressed` plugin is not packaged for Debian's ROS; without it the
  // compressed topic is subscribed and decoded here, so `~image_transport: compressed` works either way.
  void subscribeImages(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
    image_transport::ImageTransport it(nh);
    std::string transport;
    pnh.param<std::string>("image_transport", transport, "raw");
    const auto loadable = it.getLoadableTransports();
    const bool plugin = std::find(loadable.begin(), loadable.end(), "image_transport/" + transport) != loadable.end();
    if (transport == "compressed" && !plugin) {
      const std::string topic = nh.resolveName("image") + "/compressed";
      compressed_sub_ = nh.subscribe<sensor_msgs::CompressedImage>(
          topic, settings_.queue_size, [this](const sensor_msgs::CompressedImageConstPtr& m) { enqueue({nullptr, m, nullptr}); });
      NODELET_INFO("subscribed to %s (compressed images, decoded by mild_lcd)", topic.c_str());
      return;
    }
    image_sub_ = it.subscribe("image", settings_.queue_size, [this](const sensor_msgs::ImageConstPtr& m) { enqueue({m, nullptr, nullptr}); },
                              ros::VoidPtr(), image_transport::TransportHints(transport, ros::TransportHints(), pnh));
    NODELET_INFO("subscribed to %s (transport %s)", image_sub_.getTopic().c_str(), transport.c_str());
  }

  // Callbacks only queue: the nodelet manager's threads are never held up by detection.
  void enqueue(Input item) {
    if (!queue_->push(std::move(item))) {
      NODELET_WARN_THROTTLE(2.0, "input queue full (queue_size %d): dropped the oldest keyframe, %zu dropped so far",
                            settings_.queue_size, queue_->dropped());
    }
  }

  void workerLoop() {
    while (auto item = queue_->pop()) {
      process(*item);
      queue_->done();
    }
  }

  void process(const Input& input) {
    std_msgs::Header header;
    mild::DetectionResult result;
    cv::Mat query_image;
    std::optional<DatabaseSnapshot> snapshot;
    try {
      std::lock_guard<std::mutex> lock(detector_mutex_);
      if (input.image || input.compressed) {
        header = input.image ? input.image->header : input.compressed->header;
        const DecodedImage decoded = input.image ? imageFromMsg(*input.image) : imageFromMsg(*input.compressed);
        result = detector_->process(decoded.image, decoded.format, header.stamp.toSec());
        query_image = decoded.image;
      } else {
        const auto& keyframe = input.keyframe;
        header = keyframe->header;
        std::optional<uint64_t> id;
        if (keyframe->has_id) id = keyframe->id;
        result = detector_->process(featuresFromMsg(*keyframe), header.stamp.toSec(), id);
      }
      const auto stamp_of = [this](uint64_t id) {
        auto k = detector_->find(id);
        return k ? detector_->record(*k).stamp : 0.0;
      };
      loop_pub_.publish(loopClosureToMsg(result, header, detector_->size(), stamp_of));
      rememberForDebug(result.query_id, query_image);
      if (debug_pub_.getNumSubscribers() > 0) publishDebugImage(result, header);
      // memoryBytes() walks every keyframe, so at most once a second; under a steady stream
      // the diagnostics would otherwise never find the detector free and go stale.
      const auto now = std::chrono::steady_clock::now();
      if (now >= next_snapshot_) {
        snapshot = snapshotOfDatabase();
        next_snapshot_ = now + std::chrono::seconds(1);
        // The index's arrays grow by reallocation; glibc keeps the smaller copies they leave
        // behind in its heap, where nothing else fits them, and the process would grow about 2.5
        // times as fast as the map. Hand such free pages back (soak: see README). Here, once a
        // second, rather than in the core after every merge: a trim walks the whole heap, and
        // trimming per merge made inserting a keyframe four times slower (4.3 -> 16.5 ms).
        malloc_trim(0);
      }
    } catch (const mild::InvalidInput& e) {
      ++rejected_;
      NODELET_WARN_THROTTLE(2.0, "rejected keyframe (stamp %.3f): %s (%zu rejected so far)", header.stamp.toSec(), e.what(),
                            rejected_.load());
      return;
    } catch (const std::exception& e) {
      ++rejected_;
      NODELET_ERROR_THROTTLE(2.0, "keyframe (stamp %.3f) failed: %s", header.stamp.toSec(), e.what());
      return;
    }
    std::lock_guard<std::mutex> lock(stats_mutex_);
    if (snapshot) database_snapshot_ = *snapshot;
    ++processed_;
    last_ms_ = result.stats.extract_ms + result.stats.query_ms + result.stats.filter_ms + result.stats.verify_ms;
    total_ms_ += last_ms_;
    last_query_ms_ = result.stats.query_ms;
    total_query_ms_ += last_query_ms_;
  }

  // Half-resolution grey copies of the latest keyframes, for drawing a candidate next to its query.
  void rememberForDebug(uint64_t id, const cv::Mat& image) {
    if (settings_.debug_image_cache == 0 || image.empty()) return;
    cv::Mat small;
    cv::resize(mild::toGray(image, image.channels() == 1 ? mild::PixelFormat::kGray
                                    : image.channels() == 3 ? mild::PixelFormat::kBgr : mild::PixelFormat::kBgra),
               small, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
    debug_cache_[id] = small;
    debug_order_.push_back(id);
    while (debug_order_.size() > static_cast<size_t>(settings_.debug_image_cache)) {
      debug_cache_.erase(debug_order_.front());
      debug_order_.pop_front();
    }
  }

  // Query (left) and best candidate (right) with the inlier matches; called with the detector locked.
  void publishDebugImage(const mild::DetectionResult& result, const std_msgs::Header& header) {
    auto left = debug_cache_.find(result.query_id);
    if (left == debug_cache_.end()) return;
    cv::Mat canvas;
    const cv::Mat& query = left->second;
    if (result.candidates.empty() || !debug_cache_.count(result.candidates.front().id)) {
      cv::cvtColor(query, canvas, cv::COLOR_GRAY2BGR);
      cv::putText(canvas, "no candidate", cv::Point(5, 15), cv::FONT_HERSHEY_PLAIN, 1.0, cv::Scalar(0, 0, 255));
    } else {
      const mild::LoopCandidate& best = result.candidates.front();
      const mild::GeometricCheck check =
          match_verifier_->check(detector_->features(result.query_index), detector_->features(best.index));
      auto half = [](std::vector<cv::KeyPoint> k) {
        for (auto& p : k) p.pt *= 0.5f;
        return k;
      };
      std::vector<cv::DMatch> inliers;
      for (size_t i = 0; i < check.matches.size(); ++i) {
        if (!check.inlier_mask.empty() && check.inlier_mask[i]) {
          inliers.emplace_back(check.matches[i].query, check.matches[i].train, static_cast<float>(check.matches[i].distance));
        }
      }
      cv::drawMatches(query, half(detector_->record(result.query_index).keypoints), debug_cache_[best.id],
                      half(detector_->record(best.index).keypoints), inliers, canvas, cv::Scalar(0, 255, 0),
                      cv::Scalar(120, 120, 120));
      const std::string label = "id " + std::to_string(result.query_id) + " -> " + std::to_string(best.id) +
                                "  p=" + std::to_string(best.probability).substr(0, 5) + "  inliers " +
                                std::to_string(check.verification.inliers);
      cv::putText(canvas, label, cv::Point(5, 15), cv::FONT_HERSHEY_PLAIN, 1.0,
                  best.verification.verified ? cv::Scalar(0, 200, 0) : cv::Scalar(0, 0, 255));
    }
    debug_pub_.publish(cv_bridge::CvImage(header, sensor_msgs::image_encodings::BGR8, canvas).toImageMsg());
  }

  bool sparseMatchService(mild_lcd::SparseMatch::Request& request, mild_lcd::SparseMatch::Response& response) {
    std::lock_guard<std::mutex> lock(detector_mutex_);
    const auto stored = [this](uint64_t id) -> std::optional<mild::Features> {
      auto k = detector_->find(id);
      if (!k) return std::nullopt;
      return detector_->features(*k);
    };
    response = sparseMatch(request, stored, *match_verifier_);
    if (!response.success) NODELET_WARN_THROTTLE(2.0, "sparse_match: %s", response.message.c_str());
    return true;  // failures are reported in the response, not as a failed call
  }

  bool resetService(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
    const size_t pending = queue_->clear();
    std::lock_guard<std::mutex> lock(detector_mutex_);
    const size_t keyframes = detector_->size();
    detector_->reset();
    debug_cache_.clear();
    debug_order_.clear();
    response.success = true;
    response.message = "cleared " + std::to_string(keyframes) + " keyframes and " + std::to_string(pending) +
                       " waiting in the queue";
    NODELET_INFO("reset: %s", response.message.c_str());
    return true;
  }

  std::string databasePath(const std::string& requested) const {
    return requested.empty() ? settings_.database_path : requested;
  }

  bool saveService(mild_lcd::SaveDatabase::Request& request, mild_lcd::SaveDatabase::Response& response) {
    const std::string path = databasePath(request.path);
    if (path.empty()) {
      response.message = "no path given and no ~database_path set";
      return true;
    }
    std::lock_guard<std::mutex> lock(detector_mutex_);
    try {
      mild::saveDetector(*detector_, path);
      response.success = true;
      response.message = "saved " + std::to_string(detector_->size()) + " keyframes to " + path;
      NODELET_INFO("%s", response.message.c_str());
    } catch (const mild::InvalidInput& e) {
      response.message = e.what();
      NODELET_WARN("save_database: %s", e.what());
    }
    return true;
  }

  bool loadService(mild_lcd::LoadDatabase::Request& request, mild_lcd::LoadDatabase::Response& response) {
    const std::string path = databasePath(request.path);
    std::lock_guard<std::mutex> lock(detector_mutex_);
    try {
      if (path.empty()) throw mild::InvalidInput("no path given and no ~database_path set");
      response.message = mild::loadDetector(*detector_, path, request.continue_session).message;
      response.success = true;
      debug_cache_.clear();
      debug_order_.clear();
      NODELET_INFO("%s", response.message.c_str());
    } catch (const mild::InvalidInput& e) {
      response.message = e.what();  // the database is as it was
      NODELET_WARN("load_database: %s", e.what());
    }
    response.keyframes = static_cast<uint32_t>(detector_->size());
    return true;
  }

  struct DatabaseSnapshot {
    size_t keyframes = 0, features = 0, memory_bytes = 0, discarded_buckets = 0;
  };
  // Called with detector_mutex_ held.
  DatabaseSnapshot snapshotOfDatabase() const {
    return {detector_->size(), detector_->database().featureCount(), detector_->memoryBytes(),
            detector_->database().index().discardedBuckets()};
  }

  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
    std::optional<DatabaseSnapshot> fresh;
    {
      // Never wait for a keyframe in progress: a busy worker refreshes the snapshot itself.
      std::unique_lock<std::mutex> lock(detector_mutex_, std::try_to_lock);
      if (lock.owns_lock()) fresh = snapshotOfDatabase();
    }
    const size_t dropped = queue_->dropped(), rejected = rejected_.load(), depth = queue_->size();
    std::lock_guard<std::mutex> lock(stats_mutex_);
    if (fresh) database_snapshot_ = *fresh;
    if (dropped > reported_dropped_ || rejected > reported_rejected_) {
      status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN, "%zu dropped, %zu rejected keyframes since start", dropped,
                      rejected);
    } else {
      status.summary(diagnostic_msgs::DiagnosticStatus::OK, "running");
    }
    reported_dropped_ = dropped;
    reported_rejected_ = rejected;
    status.add("database keyframes", database_snapshot_.keyframes);
    status.add("database features", database_snapshot_.features);
    status.add("memory (MB)", static_cast<double>(database_snapshot_.memory_bytes) / 1e6);
    status.add("discarded buckets", database_snapshot_.discarded_buckets);
    status.add("processed keyframes", processed_);
    status.add("queue depth", depth);
    status.add("queue capacity", queue_->capacity());
    status.add("dropped keyframes", dropped);
    status.add("rejected keyframes", rejected);
    status.add("last query (ms)", last_query_ms_);
    status.add("mean query (ms)", processed_ ? total_query_ms_ / static_cast<double>(processed_) : 0.0);
    status.add("last keyframe (ms)", last_ms_);
    status.add("mean keyframe (ms)", processed_ ? total_ms_ / static_cast<double>(processed_) : 0.0);
  }

  NodeletSettings settings_;
  std::unique_ptr<mild::LoopDetector> detector_;
  std::unique_ptr<mild::GeometricVerifier> match_verifier_;
  std::mutex detector_mutex_;  // detector_, match_verifier_, debug cache
  std::unique_ptr<mild::BoundedQueue<Input>> queue_;
  std::thread worker_;

  std::unordered_map<uint64_t, cv::Mat> debug_cache_;
  std::deque<uint64_t> debug_order_;

  image_transport::Subscriber image_sub_;
  ros::Subscriber compressed_sub_, keyframe_sub_;
  ros::Publisher loop_pub_;
  image_transport::Publisher debug_pub_;
  ros::ServiceServer match_srv_, reset_srv_, save_srv_, load_srv_;
  std::unique_ptr<diagnostic_updater::Updater> updater_;
  ros::WallTimer diagnostics_timer_;

  std::atomic<size_t> rejected_{0};
  std::mutex stats_mutex_;
  size_t processed_ = 0, reported_dropped_ = 0, reported_rejected_ = 0;
  double last_ms_ = 0.0, total_ms_ = 0.0, last_query_ms_ = 0.0, total_query_ms_ = 0.0;
  DatabaseSnapshot database_snapshot_;                      // under stats_mutex_
  std::chrono::steady_clock::time_point next_snapshot_{};  // worker only
};

}  // namespace mild_lcd

PLUGINLIB_EXPORT_CLASS(mild_lcd::LoopClosureNodelet, nodelet::Nodelet)
