// mild_lcd/PoseGraphNodelet: the example back-end. Wiring only: keyframes and their loops from
// `loop_closure` (mild_lcd/LoopClosure, one per keyframe), each keyframe's pose from `odom` (or tf
// odom -> base) at its stamp, the camera's mounting from tf; the waiting room, the chains and the
// pose graph are ROS-free (backend/keyframe_admission.hpp, graph_builder.hpp, pose_graph.hpp).
// Publishes the corrected keyframe trajectory (`trajectory`, nav_msgs/Path in the map frame), the
// keyframes' odometry poses as they were (`odometry_path`, in the map frame as if map = odom: the
// drift the graph removed), the loop edges (`loop_edges`, visualization_msgs/MarkerArray: green
// kept, red rejected by the robust loss), tf map -> odom, and diagnostics (every keyframe received,
// in the graph, waiting or dropped by cause; refused inputs; loops; solves and update time).
//
// It shares a manager with the detector, so nothing a publisher sends may stop it: callbacks only
// validate and queue (under one short lock), and the graph is updated and published by its own
// thread, one solve per batch of keyframes, the O(n) paths at most publish_rate times a second.

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>
#include <thread>

#include <diagnostic_updater/diagnostic_updater.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>
#include <pluginlib/class_list_macros.hpp>

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/backend/graph_builder.hpp"
#include "mild_lcd/backend/keyframe_admission.hpp"
#include "mild_lcd/ros/settings/pose_graph_settings.hpp"
#include "mild_lcd/ros/settings/ros_parameter_source.hpp"

namespace mild_lcd {
namespace {

using mild::backend::Pose2;

constexpr double kTfHistorySeconds = 120.0;

geometry_msgs::Quaternion yawQuaternion(double yaw) {
  geometry_msgs::Quaternion q;
  q.w = std::cos(yaw / 2);
  q.z = std::sin(yaw / 2);
  return q;
}

geometry_msgs::PoseStamped poseStamped(const Pose2& p, int64_t stamp_ns, const std::string& frame) {
  geometry_msgs::PoseStamped s;
  s.header.stamp.fromNSec(static_cast<uint64_t>(stamp_ns));
  s.header.frame_id = frame;
  s.pose.position.x = p.x;
  s.pose.position.y = p.y;
  s.pose.orientation = yawQuaternion(p.yaw);
  return s;
}

Eigen::Quaterniond quaternionOf(const geometry_msgs::Quaternion& q) { return {q.w, q.x, q.y, q.z}; }

int64_t nowNs() { return static_cast<int64_t>(ros::Time::now().toNSec()); }

// The candidates the graph may use as loops, as the ROS-free input.
mild::backend::KeyframeInput keyframeInput(const LoopClosure& msg, bool use_all_verified) {
  mild::backend::KeyframeInput k;
  k.stamp_ns = static_cast<int64_t>(msg.header.stamp.toNSec());
  k.id = msg.query_id;
  k.session = msg.query_session;
  k.robot = msg.query_robot;
  k.camera_frame = msg.header.frame_id;
  for (const LoopCandidate& c : msg.candidates) {
    if (!c.has_relative_pose || !(c.accepted || (use_all_verified && c.verified))) continue;
    mild::backend::LoopInput loop;
    loop.candidate = c.id;
    loop.session = c.session;
    loop.robot = c.robot;
    loop.measurement.rotation = quaternionOf(c.relative_rotation);
    loop.measurement.translation =
        Eigen::Vector3d(c.relative_translation.x, c.relative_translation.y, c.relative_translation.z);
    loop.measurement.metric = c.metric_translation;
    k.loops.push_back(loop);
  }
  return k;
}

double percentile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  const size_t k = std::min(values.size() - 1, static_cast<size_t>(q * static_cast<double>(values.size())));
  std::nth_element(values.begin(), values.begin() + static_cast<long>(k), values.end());
  return values[k];
}

}  // namespace

class PoseGraphNodelet : public nodelet::Nodelet {
 public:
  ~PoseGraphNodelet() override {
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      stopping_ = true;
    }
    input_ready_.notify_all();
    if (worker_.joinable()) worker_.join();
  }

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      settings_ = PoseGraphSettings::load(RosParameterSource(pnh));
    } catch (const std::exception& e) {
      NODELET_FATAL("not starting: %s", e.what());
      return;
    }
    mild::backend::AdmissionParams admission;
    admission.odometry_wait = settings_.odometry_wait;
    admission.max_future_stamp = settings_.max_future_stamp;
    admission.max_waiting = static_cast<size_t>(settings_.max_waiting);
    admission.max_coordinate = settings_.graph.max_coordinate;
    admission.robot = settings_.robot;
    admission_ = std::make_unique<mild::backend::KeyframeAdmission>(admission);
    mild::backend::BuilderParams builder;
    builder.max_odometry_step = settings_.max_odometry_step;
    builder_ = std::make_unique<mild::backend::GraphBuilder>(settings_.graph, builder);

    // tf's default 10 s of history is less than a busy detector's lag: a keyframe answered 10 s after
    // its stamp would find no pose and be dropped. Two minutes, as the odometry topic's buffer holds more.
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(kTfHistorySeconds));
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    trajectory_pub_ = nh.advertise<nav_msgs::Path>("trajectory", 1, true);
    odometry_path_pub_ = nh.advertise<nav_msgs::Path>("odometry_path", 1, true);
    markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("loop_edges", 1, true);
    diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
    diagnostics_->setHardwareID("mild_lcd_pose_graph");
    diagnostics_->add("pose graph", this, &PoseGraphNodelet::report);
    // force_update on wall time: update() waits for ros::Time to move, and simulated time stands
    // still once a bag has played, when the final counts matter most.
    diagnostics_timer_ = nh.createWallTimer(ros::WallDuration(1.0),
                                            [this](const ros::WallTimerEvent&) { diagnostics_->force_update(); });
    if (settings_.use_odometry_topic) {
      odom_sub_ = nh.subscribe("odom", 1000, &PoseGraphNodelet::onOdometry, this);
    }
    loop_sub_ = nh.subscribe("loop_closure", 1000, &PoseGraphNodelet::onLoopClosure, this);
    worker_ = std::thread([this] { run(); });
    NODELET_INFO("pose graph: keyframes from loop_closure, poses from %s, %s loops, loss %s",
                 settings_.use_odometry_topic ? "odom" : "tf", settings_.use_all_verified ? "verified" : "accepted",
                 settings_.graph.robust_loss.c_str());
  }

  // Callbacks validate and queue, nothing more: the update thread does the rest.
  void onOdometry(const nav_msgs::Odometry::ConstPtr& msg) {
    const auto& p = msg->pose.pose.position;
    bool accepted = false;
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      accepted = admission_->addOdometry(static_cast<int64_t>(msg->header.stamp.toNSec()),
                                         Eigen::Vector3d(p.x, p.y, p.z), quaternionOf(msg->pose.pose.orientation));
    }
    if (!accepted) {
      NODELET_WARN_THROTTLE(5.0,
                            "pose graph: odometry at %.3f refused: not finite, beyond graph/max_coordinate "
                            "(%g m) or not a rotation (counted in the diagnostics)",
                            msg->header.stamp.toSec(), settings_.graph.max_coordinate);
    }
    input_ready_.notify_one();
  }

  void onLoopClosure(const LoopClosure::ConstPtr& msg) {
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      admission_->addKeyframe(keyframeInput(*msg, settings_.use_all_verified), nowNs());
    }
    input_ready_.notify_one();
  }

  // The pose from tf at the keyframe's exact stamp (nanoseconds: a stamp rounded through a double
  // misses the transform tf holds at it).
  std::optional<Pose2> tfPoseAt(int64_t stamp_ns) {
    try {
      const auto t = tf_buffer_->lookupTransform(settings_.odom_frame, settings_.base_frame,
                                                 ros::Time().fromNSec(static_cast<uint64_t>(stamp_ns)));
      const auto& p = t.transform.translation;
      const std::optional<Pose2> pose = mild::backend::planarPose(
          Eigen::Vector3d(p.x, p.y, p.z), quaternionOf(t.transform.rotation), settings_.graph.max_coordinate);
      // An invalid transform is a pose all the same: the waiting room refuses and counts it.
      return pose ? pose : Pose2{std::nan(""), 0.0, 0.0};
    } catch (const tf2::TransformException&) {
      return std::nullopt;
    }
  }

  void run() {
    const ros::WallDuration period(1.0 / settings_.tf_rate);
    while (true) {
      std::vector<mild::backend::ReadyKeyframe> ready;
      {
        std::unique_lock<std::mutex> lock(input_mutex_);
        input_ready_.wait_for(lock, std::chrono::duration<double>(period.toSec()));
        if (stopping_) return;
        try {
          if (settings_.use_odometry_topic) {
            ready = admission_->takeReady(nowNs());
          } else {
            ready = admission_->takeReady(nowNs(), [this](int64_t stamp) { return tfPoseAt(stamp); });
          }
        } catch (const std::exception& e) {
          NODELET_ERROR_THROTTLE(5.0, "pose graph: %s", e.what());
        }
      }
      try {
        update(std::move(ready));
      } catch (const std::exception& e) {
        // Nothing above should throw; if it does, the node goes on with the next batch.
        NODELET_ERROR_THROTTLE(5.0, "pose graph: update failed: %s", e.what());
      }
    }
  }

  void update(std::vector<mild::backend::ReadyKeyframe> ready) {
    for (auto& r : ready) held_.push_back(std::move(r));
    if (!held_.empty() && !builder_->started() && !startGraph(held_.front().keyframe)) return;
    if (!held_.empty()) {
      const mild::backend::BatchResult result = builder_->add(std::move(held_));
      held_.clear();
      if (result.solved && result.stats.failed) {
        NODELET_WARN_THROTTLE(5.0, "pose graph: a solve failed; the estimates from before it are kept");
      }
      if (result.added > 0 || result.solved) dirty_ = true;
      std::lock_guard<std::mutex> lock(stats_mutex_);
      update_ms_.push_back(result.update_ms);
      if (update_ms_.size() > 1000) update_ms_.pop_front();
      last_batch_ = result.added;
    }
    {
      mild::backend::BackendCounters counters;
      {
        std::lock_guard<std::mutex> lock(input_mutex_);
        admission_->addCountersTo(counters);
      }
      builder_->addCountersTo(counters);
      warnAboutDrops(counters);
      std::lock_guard<std::mutex> lock(stats_mutex_);
      counters_ = counters;
    }
    const ros::WallTime now = ros::WallTime::now();
    if (dirty_ && (now - last_publish_).toSec() >= 1.0 / settings_.publish_rate) {
      publish();
      dirty_ = false;
      last_publish_ = now;
    }
    broadcastCorrection();
  }

  // A warning per drop, throttled, naming the cause; the diagnostics count every one.
  void warnAboutDrops(const mild::backend::BackendCounters& c) {
    if (c.dropped() == reported_drops_ && c.loops_refused == reported_refused_) return;
    NODELET_WARN_THROTTLE(
        5.0,
        "pose graph: %lu keyframes dropped (no odometry %lu, future stamp %lu, duplicate %lu, "
        "odometry jump %lu, invalid pose %lu, other robot %lu, queue full %lu), %lu loops refused",
        static_cast<unsigned long>(c.dropped()), static_cast<unsigned long>(c.dropped_no_odometry),
        static_cast<unsigned long>(c.dropped_future_stamp), static_cast<unsigned long>(c.dropped_duplicate),
        static_cast<unsigned long>(c.dropped_odometry_jump), static_cast<unsigned long>(c.dropped_invalid_pose),
        static_cast<unsigned long>(c.dropped_other_robot), static_cast<unsigned long>(c.dropped_queue_full),
        static_cast<unsigned long>(c.loops_refused));
    reported_drops_ = c.dropped();
    reported_refused_ = c.loops_refused;
  }

  // The camera's mounting, once: tf base_frame -> camera frame, else (after odometry_wait) a
  // forward-looking camera at the base's origin.
  bool startGraph(const mild::backend::KeyframeInput& first) {
    const std::string frame = settings_.camera_frame.empty() ? first.camera_frame : settings_.camera_frame;
    mild::backend::Extrinsics e = mild::backend::Extrinsics::forwardLooking();
    try {
      const auto t = tf_buffer_->lookupTransform(settings_.base_frame, frame, ros::Time(0));
      const Eigen::Quaterniond q = quaternionOf(t.transform.rotation);
      if (q.coeffs().allFinite() && q.norm() > 0.5)
        e.rotation = q.normalized().toRotationMatrix();
      else
        e.rotation = Eigen::Matrix3d::Constant(std::nan(""));
      e.translation = Eigen::Vector3d(t.transform.translation.x, t.transform.translation.y, t.transform.translation.z);
      if (builder_->start(e, settings_.max_extrinsics_distance)) {
        NODELET_INFO("pose graph: camera %s at (%.2f, %.2f, %.2f) in %s", frame.c_str(), e.translation.x(),
                     e.translation.y(), e.translation.z(), settings_.base_frame.c_str());
      } else {
        NODELET_WARN(
            "pose graph: tf %s -> %s refused (not finite, not a rotation, or farther than "
            "~max_extrinsics_distance %g m): a forward-looking camera at the base's origin is assumed",
            settings_.base_frame.c_str(), frame.c_str(), settings_.max_extrinsics_distance);
      }
      return true;
    } catch (const tf2::TransformException& ex) {
      if (waiting_for_mounting_since_.isZero()) waiting_for_mounting_since_ = ros::WallTime::now();
      if ((ros::WallTime::now() - waiting_for_mounting_since_).toSec() <= settings_.odometry_wait) return false;
      NODELET_WARN("pose graph: no tf %s -> %s (%s): a forward-looking camera at the base's origin is assumed",
                   settings_.base_frame.c_str(), frame.c_str(), ex.what());
    }
    builder_->start(mild::backend::Extrinsics::forwardLooking(), settings_.max_extrinsics_distance);
    return true;
  }

  void publish() {
    const mild::backend::PoseGraph2D& graph = builder_->graph();
    if (graph.size() == 0) return;
    const std::vector<int64_t>& stamps = builder_->stamps();
    auto path = boost::make_shared<nav_msgs::Path>();
    auto odometry = boost::make_shared<nav_msgs::Path>();
    path->header.frame_id = odometry->header.frame_id = settings_.map_frame;
    path->header.stamp.fromNSec(static_cast<uint64_t>(stamps.back()));
    odometry->header.stamp = path->header.stamp;
    const std::vector<Pose2> estimates = graph.estimates();
    path->poses.reserve(estimates.size());
    odometry->poses.reserve(estimates.size());
    for (size_t i = 0; i < estimates.size(); ++i) {
      path->poses.push_back(poseStamped(estimates[i], stamps[i], settings_.map_frame));
      odometry->poses.push_back(poseStamped(graph.odometry(i), stamps[i], settings_.map_frame));
    }
    trajectory_pub_.publish(path);
    odometry_path_pub_.publish(odometry);

    auto markers = boost::make_shared<visualization_msgs::MarkerArray>();
    for (int kept = 1; kept >= 0; --kept) {
      visualization_msgs::Marker m;
      m.header = path->header;
      m.ns = kept ? "loops_kept" : "loops_rejected";
      m.id = kept;
      m.type = visualization_msgs::Marker::LINE_LIST;
      m.action = visualization_msgs::Marker::ADD;
      m.pose.orientation.w = 1.0;
      m.scale.x = 0.04;
      m.color.a = 0.8f;
      m.color.r = kept ? 0.1f : 0.9f;
      m.color.g = kept ? 0.8f : 0.1f;
      m.color.b = 0.1f;
      for (const auto& l : graph.loops()) {
        if (l.inlier != static_cast<bool>(kept)) continue;
        for (uint64_t node : {l.query, l.candidate}) {  // the builder numbers nodes in graph order
          geometry_msgs::Point p;
          p.x = estimates[node].x;
          p.y = estimates[node].y;
          m.points.push_back(p);
        }
      }
      markers->markers.push_back(m);
    }
    markers_pub_.publish(markers);
  }

  void broadcastCorrection() {
    if (!settings_.publish_tf || !builder_->started() || builder_->graph().size() == 0) return;
    const ros::WallTime wall = ros::WallTime::now();
    if ((wall - last_broadcast_).toSec() < 1.0 / settings_.tf_rate) return;
    last_broadcast_ = wall;
    const Pose2 c = builder_->graph().mapToOdom();
    geometry_msgs::TransformStamped t;
    ros::Time newest;
    newest.fromNSec(static_cast<uint64_t>(builder_->stamps().back()));
    // Future-dated a little, as localisation nodes do, so that lookups at "now" succeed between broadcasts.
    t.header.stamp = std::max(ros::Time::now(), newest) + ros::Duration(1.0 / settings_.tf_rate);
    // tf refuses a transform at a stamp it already has (simulated time stands still after a bag).
    if (t.header.stamp <= last_tf_stamp_ && c.x == last_tf_.x && c.y == last_tf_.y && c.yaw == last_tf_.yaw) return;
    if (t.header.stamp <= last_tf_stamp_) t.header.stamp = last_tf_stamp_ + ros::Duration(1e-3);
    last_tf_stamp_ = t.header.stamp;
    last_tf_ = c;
    t.header.frame_id = settings_.map_frame;
    t.child_frame_id = settings_.odom_frame;
    t.transform.translation.x = c.x;
    t.transform.translation.y = c.y;
    t.transform.rotation = yawQuaternion(c.yaw);
    broadcaster_.sendTransform(t);
  }

  void report(diagnostic_updater::DiagnosticStatusWrapper& status) {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    const std::vector<double> times(update_ms_.begin(), update_ms_.end());
    for (const auto& [name, value] : counters_.named()) status.add(name, value);
    status.add("update ms median", percentile(times, 0.5));
    status.add("update ms p95", percentile(times, 0.95));
    status.add("update keyframes", last_batch_);
    if (counters_.solves_failed > 0 || counters_.dropped() > 0) {
      status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "keyframes dropped or solves failed (see the counts)");
    } else {
      status.summary(diagnostic_msgs::DiagnosticStatus::OK, "every keyframe received is in the graph or waiting");
    }
  }

  PoseGraphSettings settings_;
  // Input side: the callbacks and the update thread.
  std::mutex input_mutex_;
  std::condition_variable input_ready_;
  bool stopping_ = false;
  std::unique_ptr<mild::backend::KeyframeAdmission> admission_;
  // The update thread's own.
  std::unique_ptr<mild::backend::GraphBuilder> builder_;
  std::vector<mild::backend::ReadyKeyframe> held_;  // ready before the camera's mounting was known
  ros::WallTime waiting_for_mounting_since_;
  bool dirty_ = false;
  ros::WallTime last_publish_, last_broadcast_;
  ros::Time last_tf_stamp_;
  Pose2 last_tf_;
  uint64_t reported_drops_ = 0, reported_refused_ = 0;
  // Shared with the diagnostics.
  std::mutex stats_mutex_;
  mild::backend::BackendCounters counters_;
  std::deque<double> update_ms_;
  size_t last_batch_ = 0;

  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  tf2_ros::TransformBroadcaster broadcaster_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  ros::WallTimer diagnostics_timer_;
  ros::Subscriber odom_sub_, loop_sub_;
  ros::Publisher trajectory_pub_, odometry_path_pub_, markers_pub_;
  std::thread worker_;
};

}  // namespace mild_lcd

PLUGINLIB_EXPORT_CLASS(mild_lcd::PoseGraphNodelet, nodelet::Nodelet)
