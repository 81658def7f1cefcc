// mild_lcd/PoseGraphNodelet: the example back-end. Wiring only: keyframes and their loops from
// `loop_closure` (mild_lcd/LoopClosure, one per keyframe), each keyframe's pose from `odom` (or tf
// odom -> base) at its stamp, the camera's mounting from tf; the pose graph itself is
// mild::backend::PoseGraph2D (ROS-free). Publishes the corrected keyframe trajectory (`trajectory`,
// nav_msgs/Path in the map frame), the keyframes' odometry poses as they were (`odometry_path`, in
// the map frame as if map = odom: the drift the graph removed), the loop edges (`loop_edges`,
// visualization_msgs/MarkerArray: green kept, red rejected by the robust loss) and tf map -> odom.

#include <deque>
#include <memory>
#include <mutex>

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
#include "mild_lcd/backend/pose_graph.hpp"
#include "mild_lcd/ros/pose_graph_settings.hpp"
#include "mild_lcd/ros/ros_parameter_source.hpp"

namespace mild_lcd {
namespace {

using mild::backend::Pose2;

double yawOf(const geometry_msgs::Quaternion& q) {
  return std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
}

geometry_msgs::Quaternion yawQuaternion(double yaw) {
  geometry_msgs::Quaternion q;
  q.w = std::cos(yaw / 2);
  q.z = std::sin(yaw / 2);
  return q;
}

geometry_msgs::PoseStamped poseStamped(const Pose2& p, const ros::Time& stamp, const std::string& frame) {
  geometry_msgs::PoseStamped s;
  s.header.stamp = stamp;
  s.header.frame_id = frame;
  s.pose.position.x = p.x;
  s.pose.position.y = p.y;
  s.pose.orientation = yawQuaternion(p.yaw);
  return s;
}

}  // namespace

class PoseGraphNodelet : public nodelet::Nodelet {
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
    tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    trajectory_pub_ = nh.advertise<nav_msgs::Path>("trajectory", 1, true);
    odometry_path_pub_ = nh.advertise<nav_msgs::Path>("odometry_path", 1, true);
    markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("loop_edges", 1, true);
    if (settings_.use_odometry_topic) {
      odom_sub_ = nh.subscribe("odom", 200, &PoseGraphNodelet::onOdometry, this);
    }
    loop_sub_ = nh.subscribe("loop_closure", 100, &PoseGraphNodelet::onLoopClosure, this);
    // Also retries the keyframes waiting for their pose (with tf, no odometry message wakes them).
    tf_timer_ = nh.createTimer(ros::Duration(1.0 / settings_.tf_rate), [this](const ros::TimerEvent&) {
      std::lock_guard<std::mutex> lock(mutex_);
      processPending();
      broadcastCorrection();
    });
    NODELET_INFO("pose graph: keyframes from loop_closure, poses from %s, %s loops, loss %s",
                 settings_.use_odometry_topic ? "odom" : "tf", settings_.use_all_verified ? "verified" : "accepted",
                 settings_.graph.robust_loss.c_str());
  }

  void onOdometry(const nav_msgs::Odometry::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!odometry_.empty() && msg->header.stamp <= odometry_.back().first) {
      if (msg->header.stamp < odometry_.back().first) odometry_.clear();  // time went back: a bag restarted
    }
    odometry_.emplace_back(msg->header.stamp, Pose2{msg->pose.pose.position.x, msg->pose.pose.position.y,
                                                    yawOf(msg->pose.pose.orientation)});
    while (odometry_.size() > 100000) odometry_.pop_front();
    processPending();
  }

  void onLoopClosure(const LoopClosure::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_.push_back(msg);
    processPending();
  }

  // The keyframe's odometry pose at `stamp`: interpolated between the bracketing messages, or from tf.
  // nullopt while it is not known yet; dropped (with a warning) once odometry_wait has passed.
  std::optional<Pose2> odometryAt(const ros::Time& stamp, bool& give_up) {
    give_up = false;
    if (!settings_.use_odometry_topic) {
      try {
        const auto t = tf_buffer_->lookupTransform(settings_.odom_frame, settings_.base_frame, stamp);
        return Pose2{t.transform.translation.x, t.transform.translation.y, yawOf(t.transform.rotation)};
      } catch (const tf2::TransformException& e) {
        give_up = (ros::Time::now() - stamp).toSec() > settings_.odometry_wait;
        if (give_up)
          NODELET_WARN("pose graph: no tf %s at the keyframe's stamp: %s", settings_.odom_frame.c_str(), e.what());
        return std::nullopt;
      }
    }
    if (odometry_.empty() || stamp > odometry_.back().first) {
      const ros::Time newest = odometry_.empty() ? ros::Time::now() : odometry_.back().first;
      give_up = (std::max(newest, ros::Time::now()) - stamp).toSec() > settings_.odometry_wait;
      return std::nullopt;
    }
    if (stamp < odometry_.front().first) {
      give_up = true;
      return std::nullopt;
    }
    auto after = std::lower_bound(odometry_.begin(), odometry_.end(), stamp,
                                  [](const auto& o, const ros::Time& t) { return o.first < t; });
    if (after->first == stamp || after == odometry_.begin()) return after->second;
    const auto before = std::prev(after);
    const double f = (stamp - before->first).toSec() / (after->first - before->first).toSec();
    const Pose2 step = mild::backend::between(before->second, after->second);
    return mild::backend::compose(before->second, Pose2{f * step.x, f * step.y, f * step.yaw});
  }

  // The camera's mounting, once: tf base_frame -> camera frame, else (after odometry_wait) a
  // forward-looking camera at the base's origin.
  bool ensureGraph(const std::string& camera_frame, const ros::Time& stamp) {
    if (graph_) return true;
    const std::string frame = settings_.camera_frame.empty() ? camera_frame : settings_.camera_frame;
    mild::backend::Extrinsics e = mild::backend::Extrinsics::forwardLooking();
    try {
      const auto t = tf_buffer_->lookupTransform(settings_.base_frame, frame, ros::Time(0));
      const auto& q = t.transform.rotation;
      e.rotation = Eigen::Quaterniond(q.w, q.x, q.y, q.z).normalized().toRotationMatrix();
      e.translation = Eigen::Vector3d(t.transform.translation.x, t.transform.translation.y, t.transform.translation.z);
      NODELET_INFO("pose graph: camera %s at (%.2f, %.2f, %.2f) in %s", frame.c_str(), e.translation.x(),
                   e.translation.y(), e.translation.z(), settings_.base_frame.c_str());
    } catch (const tf2::TransformException& ex) {
      if ((ros::Time::now() - stamp).toSec() <= settings_.odometry_wait) return false;
      NODELET_WARN("pose graph: no tf %s -> %s (%s): a forward-looking camera at the base's origin is assumed",
                   settings_.base_frame.c_str(), frame.c_str(), ex.what());
    }
    graph_ = std::make_unique<mild::backend::PoseGraph2D>(settings_.graph, e);
    return true;
  }

  void processPending() {
    bool changed = false;
    while (!pending_.empty()) {
      const LoopClosure::ConstPtr msg = pending_.front();
      bool give_up = false;
      const std::optional<Pose2> pose = odometryAt(msg->header.stamp, give_up);
      if (!pose) {
        if (!give_up) break;
        NODELET_WARN_THROTTLE(5.0, "pose graph: no odometry at keyframe %lu's stamp; keyframe dropped",
                              static_cast<unsigned long>(msg->query_id));
        pending_.pop_front();
        continue;
      }
      if (!ensureGraph(msg->header.frame_id, msg->header.stamp)) break;
      pending_.pop_front();
      changed |= addKeyframe(*msg, *pose);
    }
    if (changed) publish();
  }

  bool addKeyframe(const LoopClosure& msg, const Pose2& pose) {
    if (graph_->contains(msg.query_id)) return false;
    graph_->addKeyframe(msg.query_id, pose);
    stamps_.push_back(msg.header.stamp);
    bool added = false;
    for (const LoopCandidate& c : msg.candidates) {
      if (!c.has_relative_pose || !(c.accepted || (settings_.use_all_verified && c.verified))) continue;
      mild::backend::LoopMeasurement m;
      m.query = msg.query_id;
      m.candidate = c.id;
      m.rotation = Eigen::Quaterniond(c.relative_rotation.w, c.relative_rotation.x, c.relative_rotation.y,
                                      c.relative_rotation.z);
      m.translation = Eigen::Vector3d(c.relative_translation.x, c.relative_translation.y, c.relative_translation.z);
      m.metric = c.metric_translation;
      added |= graph_->addLoop(m);
    }
    if (added) {
      const mild::backend::UpdateStats s = graph_->optimize();
      ++updates_;
      NODELET_DEBUG("pose graph: %zu keyframes, %zu loops, update %.1f ms (%d iterations)", graph_->size(),
                    graph_->loopCount(), s.solve_ms, s.iterations);
      if (updates_ % 50 == 1) {
        NODELET_INFO("pose graph: %zu keyframes, %zu loops, update %.1f ms", graph_->size(), graph_->loopCount(),
                     s.solve_ms);
      }
    }
    return true;
  }

  void publish() {
    const auto& ids = graph_->ids();
    nav_msgs::Path path, odometry;
    path.header.frame_id = odometry.header.frame_id = settings_.map_frame;
    path.header.stamp = odometry.header.stamp = stamps_.back();
    const std::vector<Pose2> estimates = graph_->estimates();
    for (size_t i = 0; i < ids.size(); ++i) {
      path.poses.push_back(poseStamped(estimates[i], stamps_[i], settings_.map_frame));
      odometry.poses.push_back(poseStamped(graph_->odometry(i), stamps_[i], settings_.map_frame));
    }
    trajectory_pub_.publish(path);
    odometry_path_pub_.publish(odometry);

    visualization_msgs::MarkerArray markers;
    std::unordered_map<uint64_t, size_t> index;
    for (size_t i = 0; i < ids.size(); ++i) index[ids[i]] = i;
    for (int kept = 1; kept >= 0; --kept) {
      visualization_msgs::Marker m;
      m.header = path.header;
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
      for (const auto& l : graph_->loops()) {
        if (l.inlier != static_cast<bool>(kept)) continue;
        for (uint64_t id : {l.query, l.candidate}) {
          geometry_msgs::Point p;
          p.x = estimates[index[id]].x;
          p.y = estimates[index[id]].y;
          m.points.push_back(p);
        }
      }
      markers.markers.push_back(m);
    }
    markers_pub_.publish(markers);
    broadcastCorrection();
  }

  void broadcastCorrection() {
    if (!settings_.publish_tf || !graph_ || graph_->size() == 0) return;
    const Pose2 c = graph_->mapToOdom();
    geometry_msgs::TransformStamped t;
    // Future-dated a little, as localisation nodes do, so that lookups at "now" succeed between broadcasts.
    t.header.stamp = std::max(ros::Time::now(), stamps_.back()) + ros::Duration(1.0 / settings_.tf_rate);
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

  PoseGraphSettings settings_;
  std::mutex mutex_;
  std::unique_ptr<mild::backend::PoseGraph2D> graph_;
  std::vector<ros::Time> stamps_;
  std::deque<std::pair<ros::Time, Pose2>> odometry_;
  std::deque<LoopClosure::ConstPtr> pending_;
  size_t updates_ = 0;
  ros::Time last_tf_stamp_;
  Pose2 last_tf_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  tf2_ros::TransformBroadcaster broadcaster_;
  ros::Subscriber odom_sub_, loop_sub_;
  ros::Publisher trajectory_pub_, odometry_path_pub_, markers_pub_;
  ros::Timer tf_timer_;
};

}  // namespace mild_lcd

PLUGINLIB_EXPORT_CLASS(mild_lcd::PoseGraphNodelet, nodelet::Nodelet)
