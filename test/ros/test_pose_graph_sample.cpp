// rostest (pose_graph_sample.test): the example back-end on the embedded sample. A real master, one
// nodelet manager holding the detector (images + camera_info) and the pose-graph nodelet (odometry
// with drift from the bag, the camera's mounting from its static tf), `rosbag play --clock` of the
// sample bag written with odometry (pose_graph_sample_tf.test: the poses from tf instead). The
// corrected trajectory the back-end publishes is compared with the sample's poses.txt: its ATE (RMSE
// after SE(2) alignment) must be at most 0.3 x the odometry's.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>

#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <visualization_msgs/MarkerArray.h>

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/backend/trajectory.hpp"
#include "mild_lcd/offline/pose_evaluation.hpp"
#include "ros_test_support.hpp"

namespace mild_lcd::test {
namespace {

using mild::backend::Pose2;

constexpr size_t kFrames = 300;
const std::string kBag = std::string(MILD_BAG_DIR) + "/sample_corridor_odometry.bag";
const std::string kSampleDir = std::string(MILD_SOURCE_DIR) + "/sample/corridor";
constexpr double kStart = 1000.0;  // mild_make_bag's --start

double yawOf(const geometry_msgs::Quaternion& q) {
  return std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
}

// Frame index of each pose of a path (by stamp against times.txt), with its planar pose.
std::map<size_t, Pose2> byFrame(const nav_msgs::Path& path, const std::vector<double>& times) {
  std::map<size_t, Pose2> out;
  for (const auto& p : path.poses) {
    const double t = p.header.stamp.toSec() - kStart;
    const auto it = std::lower_bound(times.begin(), times.end(), t - 1e-4);
    if (it == times.end() || std::abs(*it - t) > 1e-3) continue;
    out[static_cast<size_t>(it - times.begin())] = {p.pose.position.x, p.pose.position.y, yawOf(p.pose.orientation)};
  }
  return out;
}

TEST(PoseGraphSample, CorrectsTheDrift) {
  TopicLog<mild_lcd::LoopClosure> closures("/loop_closure");
  TopicLog<nav_msgs::Path> trajectory("/trajectory", 10);
  TopicLog<nav_msgs::Path> odometry("/odometry_path", 10);
  TopicLog<visualization_msgs::MarkerArray> edges("/loop_edges", 10);
  ASSERT_TRUE(closures.waitForPublisher(30.0));
  ASSERT_TRUE(trajectory.waitForPublisher(30.0));
  // pose_graph_sample_tf.test plays no /odom (the back-end reads tf instead, and rosbag play waits
  // for a subscriber on every topic it plays).
  const std::string topics =
      ros::NodeHandle("~").param<std::string>("topics", "/camera/image /camera/camera_info /odom /tf /tf_static");
  ASSERT_EQ(playBag(kBag, topics, "--clock -r 2"), 0);
  EXPECT_TRUE(closures.waitForCount(kFrames, 120.0)) << closures.size() << " keyframes answered";
  // The back-end's last update follows the last keyframe.
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(30.0);
  while (ros::WallTime::now() < end &&
         (trajectory.size() == 0 || trajectory.messages().back().poses.size() < closures.size())) {
    ros::WallDuration(0.1).sleep();
  }
  ASSERT_GT(trajectory.size(), 0u);
  ASSERT_GT(odometry.size(), 0u);
  const nav_msgs::Path corrected = trajectory.messages().back(), raw = odometry.messages().back();
  EXPECT_GE(corrected.poses.size(), kFrames * 9 / 10) << "keyframes in the graph";

  std::vector<double> times;
  std::ifstream in(kSampleDir + "/times.txt");
  for (double t; in >> t;) times.push_back(t);
  const std::vector<mild::PlanarPose> poses = mild::loadPlanarPoses(kSampleDir + "/poses.txt");
  const auto after = byFrame(corrected, times), before = byFrame(raw, times);
  std::vector<Pose2> truth, est_after, est_before;
  for (const auto& [frame, pose] : after) {
    if (!before.count(frame)) continue;
    truth.push_back({poses[frame].x, poses[frame].y, poses[frame].yaw});
    est_after.push_back(pose);
    est_before.push_back(before.at(frame));
  }
  ASSERT_GE(truth.size(), kFrames * 9 / 10);
  const double ate_before = mild::backend::absoluteTrajectoryError(est_before, truth);
  const double ate_after = mild::backend::absoluteTrajectoryError(est_after, truth);
  size_t kept = 0, rejected = 0;
  const visualization_msgs::MarkerArray drawn = edges.messages().back();  // a copy: messages() is a temporary
  for (const auto& m : drawn.markers) (m.ns == "loops_kept" ? kept : rejected) = m.points.size() / 2;
  std::printf(
      "pose graph on the sample: %zu keyframes, ATE odometry %.3f m, corrected %.3f m (ratio %.3f), loop edges "
      "kept %zu, rejected %zu\n",
      truth.size(), ate_before, ate_after, ate_after / ate_before, kept, rejected);
  EXPECT_GT(ate_before, 0.2) << "the bag's odometry drifts";
  EXPECT_LE(ate_after, 0.3 * ate_before);
  EXPECT_GT(kept, 20u);
}

}  // namespace
}  // namespace mild_lcd::test

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_pose_graph_sample");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  ros::shutdown();
  return result;
}
