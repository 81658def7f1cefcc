// rostest (slam_example_nan_odometry.test): the example back-end must never take the detector down and
// must lose nothing silently. slam_example.launch runs the detector and the pose graph in one nodelet
// manager and plays the sample bag with odometry itself (rate 1, --wait-for-subscribers: the nodelets
// start it, not this node). After about a third of the keyframes have been answered, this node publishes
// one nav_msgs/Odometry whose pose holds NaN and inf on /odom, as a broken driver would. A back-end that
// let the pose into its graph would throw inside the shared manager and kill the detector with it. Then:
// every keyframe is still answered on /loop_closure, the back-end still publishes a finite trajectory
// that corrects the drift, and its diagnostics count the rejected message and account for every keyframe.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <string>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/backend/trajectory.hpp"
#include "mild_lcd/offline/pose_evaluation.hpp"
#include "ros_test_support.hpp"

namespace mild_lcd::test {
namespace {

using mild::backend::Pose2;

constexpr size_t kFrames = 300;
constexpr size_t kInjectAfter = 100;  // keyframes answered before the NaN odometry
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

bool finite(const geometry_msgs::Pose& p) {
  for (double v :
       {p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w}) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

// The back-end's status (its name ends with "pose graph") in the newest diagnostics that hold it, as
// key -> value; nullopt when it never reported.
using Status = std::map<std::string, std::string>;
std::optional<Status> lastPoseGraphStatus(const std::vector<diagnostic_msgs::DiagnosticArray>& arrays) {
  const std::string suffix = "pose graph";
  for (auto a = arrays.rbegin(); a != arrays.rend(); ++a) {
    for (const auto& s : a->status) {
      if (s.name.size() < suffix.size() || s.name.compare(s.name.size() - suffix.size(), suffix.size(), suffix) != 0)
        continue;
      Status values;
      for (const auto& kv : s.values) values[kv.key] = kv.value;
      return values;
    }
  }
  return std::nullopt;
}

// An integer entry of the status; -1 when missing or not a number (so that every check on it fails).
long long count(const Status& s, const std::string& key) {
  const auto it = s.find(key);
  if (it == s.end()) return -1;
  try {
    return std::stoll(it->second);
  } catch (const std::exception&) {
    return -1;
  }
}

TEST(SlamExample, SurvivesNanOdometry) {
  // Subscribed at once: the launch's player starts as soon as the nodelets listen, not when we do.
  TopicLog<mild_lcd::LoopClosure> closures("/loop_closure");
  TopicLog<nav_msgs::Path> trajectory("/trajectory", 10);
  TopicLog<nav_msgs::Path> odometry("/odometry_path", 10);
  TopicLog<diagnostic_msgs::DiagnosticArray> diagnostics("/diagnostics", 100);
  ros::NodeHandle nh;
  ros::Publisher odom_pub = nh.advertise<nav_msgs::Odometry>("/odom", 1);
  ASSERT_TRUE(closures.waitForPublisher(60.0)) << "no detector on /loop_closure";
  ASSERT_TRUE(waitForSubscriber(odom_pub, 60.0)) << "no back-end on /odom";

  ASSERT_TRUE(closures.waitForCount(kInjectAfter, 120.0)) << closures.size() << " keyframes answered";
  // Stamped at a keyframe still to come (half a second ahead on the bag's clock): the keyframe's
  // pose is then read from it (or interpolated through it), which aborted the old back-end.
  std::vector<double> frame_times;
  std::ifstream frames(kSampleDir + "/times.txt");
  for (double t; frames >> t;) frame_times.push_back(t);
  const double soon = ros::Time::now().toSec() + 0.5 - kStart;
  const auto next = std::lower_bound(frame_times.begin(), frame_times.end(), soon);
  ASSERT_NE(next, frame_times.end());
  nav_msgs::Odometry bad;
  bad.header.stamp = ros::Time(kStart + *next);
  bad.header.frame_id = "odom";
  bad.child_frame_id = "base_link";
  bad.pose.pose.position.x = std::numeric_limits<double>::quiet_NaN();
  bad.pose.pose.orientation.w = std::numeric_limits<double>::infinity();
  const size_t trajectories_before = trajectory.size();
  odom_pub.publish(bad);
  std::printf(
      "NaN odometry stamped %.3f (a keyframe's stamp) published after %zu keyframes answered, %zu trajectories\n",
      bad.header.stamp.toSec(), closures.size(), trajectories_before);

  // The detector survived: the shared manager still runs it.
  EXPECT_TRUE(closures.waitForCount(kFrames, 120.0)) << closures.size() << " of " << kFrames << " keyframes answered";

  // The back-end's final state: its diagnostics account for every keyframe it received and none
  // waits any more, and its last trajectory holds every keyframe in the graph. The trajectory is
  // throttled, with a final publish after the last change; the diagnostics come every second.
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(60.0);
  std::optional<Status> status;
  while (ros::WallTime::now() < end) {
    status = lastPoseGraphStatus(diagnostics.messages());
    if (status && count(*status, "keyframes received") >= static_cast<long long>(closures.size()) &&
        count(*status, "keyframes waiting") == 0 && trajectory.size() > 0 &&
        static_cast<long long>(trajectory.messages().back().poses.size()) >= count(*status, "keyframes in graph")) {
      break;
    }
    ros::WallDuration(0.2).sleep();
  }

  // Checked apart from the trajectory below, so that one failure does not hide the other.
  if (!status) {
    ADD_FAILURE() << "no diagnostics whose name ends with \"pose graph\" on /diagnostics";
  } else {
    const long long received = count(*status, "keyframes received"), in_graph = count(*status, "keyframes in graph"),
                    waiting = count(*status, "keyframes waiting"), dropped = count(*status, "keyframes dropped");
    std::string line;
    for (const auto& [key, value] : *status) line += (line.empty() ? "" : ", ") + key + " " + value;
    std::printf("pose graph diagnostics: %s\n", line.c_str());
    EXPECT_GE(count(*status, "odometry rejected"), 1) << "the NaN odometry was not counted";
    EXPECT_GE(in_graph, 0);
    EXPECT_GE(waiting, 0);
    EXPECT_GE(dropped, 0);
    EXPECT_EQ(received, in_graph + waiting + dropped) << "keyframes lost without a count";
    // Every answered keyframe reached the back-end in the same manager; stale diagnostics (an updater
    // driven by the simulated clock, which stops with the bag) fail here too.
    EXPECT_EQ(received, static_cast<long long>(closures.size()));
    EXPECT_EQ(waiting, 0);
  }

  ASSERT_GT(trajectory.size(), trajectories_before) << "no trajectory published after the NaN odometry";
  ASSERT_GT(odometry.size(), 0u);
  const nav_msgs::Path corrected = trajectory.messages().back(), raw = odometry.messages().back();
  EXPECT_GE(corrected.poses.size(), kFrames * 9 / 10) << "keyframes in the last trajectory";
  size_t not_finite = 0;
  for (const auto& p : corrected.poses) not_finite += finite(p.pose) ? 0 : 1;
  EXPECT_EQ(not_finite, 0u) << "poses with NaN or inf in the trajectory";

  std::vector<double> times;
  std::ifstream in(kSampleDir + "/times.txt");
  for (double t; in >> t;) times.push_back(t);
  const std::vector<mild::PlanarPose> poses = mild::loadPlanarPoses(kSampleDir + "/poses.txt");
  const auto after = byFrame(corrected, times), before = byFrame(raw, times);
  std::vector<Pose2> truth, est_after, est_before;
  for (const auto& [frame, pose] : after) {
    if (!before.count(frame)) continue;
    if (!std::isfinite(pose.x) || !std::isfinite(pose.y)) continue;  // counted above; the ATE needs numbers
    truth.push_back({poses[frame].x, poses[frame].y, poses[frame].yaw});
    est_after.push_back(pose);
    est_before.push_back(before.at(frame));
  }
  ASSERT_GE(truth.size(), kFrames * 9 / 10);
  const double ate_before = mild::backend::absoluteTrajectoryError(est_before, truth);
  const double ate_after = mild::backend::absoluteTrajectoryError(est_after, truth);
  std::printf("slam_example with NaN odometry: %zu keyframes, ATE odometry %.3f m, corrected %.3f m (ratio %.3f)\n",
              truth.size(), ate_before, ate_after, ate_after / ate_before);
  EXPECT_LT(ate_after, ate_before) << "the corrected trajectory does not correct the drift";
}

}  // namespace
}  // namespace mild_lcd::test

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_slam_example_nan_odometry");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  ros::shutdown();
  return result;
}
