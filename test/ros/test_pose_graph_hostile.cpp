// rostest (pose_graph_hostile.test): the example back-end's nodelet in a real manager, fed what a
// broken stack could send. One replay of 100 keyframes along a straight line (1 m apart, odometry
// exact): a NaN and a 1e300 m odometry message, a keyframe stamped an hour ahead, a loop 1e200 m
// long; after keyframe 60 the detector is "reset" (ids start again at 0), and the new run's loops
// name its own ids, which the first run also had. The manager must live, every keyframe must be in
// the graph or counted, the trajectory must go on after the reset, and no loop may join a new-run
// keyframe to the first run's keyframe of the same id.

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <map>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <nav_msgs/Odometry.h>
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <visualization_msgs/MarkerArray.h>

#include "mild_lcd/LoopClosure.h"
#include "ros_test_support.hpp"

namespace mild_lcd::test {
namespace {

constexpr int kFirstRun = 60, kSecondRun = 40;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

nav_msgs::Odometry odometry(const ros::Time& stamp, double x) {
  nav_msgs::Odometry o;
  o.header.stamp = stamp;
  o.header.frame_id = "odom";
  o.child_frame_id = "base_link";
  o.pose.pose.position.x = x;
  o.pose.pose.orientation.w = 1.0;
  return o;
}

// A loop to the keyframe `behind` metres back on the line: the candidate camera straight behind the
// query camera (optical z is the base's x).
LoopCandidate loopBehind(uint64_t candidate, double behind) {
  LoopCandidate c;
  c.id = candidate;
  c.accepted = c.verified = c.has_relative_pose = c.metric_translation = true;
  c.probability = 0.9;
  c.relative_rotation.w = 1.0;
  c.relative_translation.z = -behind;
  return c;
}

// The newest "pose graph" status, as name -> value.
std::map<std::string, std::string> latestStatus(const std::vector<diagnostic_msgs::DiagnosticArray>& arrays) {
  std::map<std::string, std::string> values;
  for (const auto& array : arrays) {
    for (const auto& status : array.status) {
      const std::string suffix = "pose graph";
      if (status.name.size() < suffix.size() ||
          status.name.compare(status.name.size() - suffix.size(), suffix.size(), suffix) != 0) {
        continue;
      }
      values.clear();
      for (const auto& kv : status.values) values[kv.key] = kv.value;
    }
  }
  return values;
}

uint64_t count(const std::map<std::string, std::string>& status, const std::string& key) {
  const auto it = status.find(key);
  EXPECT_NE(it, status.end()) << key;
  return it == status.end() ? 0 : std::stoull(it->second);
}

TEST(PoseGraphHostile, RefusesCountsAndKeepsGoingThroughAReset) {
  ros::NodeHandle nh;
  ros::Publisher odom_pub = nh.advertise<nav_msgs::Odometry>("odom", 1000);
  ros::Publisher loop_pub = nh.advertise<LoopClosure>("loop_closure", 1000);
  TopicLog<nav_msgs::Path> trajectory("/trajectory", 10);
  TopicLog<visualization_msgs::MarkerArray> edges("/loop_edges", 10);
  TopicLog<diagnostic_msgs::DiagnosticArray> diagnostics("/diagnostics", 100);
  ASSERT_TRUE(waitForSubscriber(odom_pub, 30.0));
  ASSERT_TRUE(waitForSubscriber(loop_pub, 30.0));
  ASSERT_TRUE(trajectory.waitForPublisher(30.0));

  ros::WallRate rate(20.0);
  for (int k = 0; k < kFirstRun + kSecondRun; ++k) {
    const bool second = k >= kFirstRun;
    const ros::Time stamp = ros::Time::now();
    odom_pub.publish(odometry(stamp, k));
    LoopClosure msg;
    msg.header.stamp = stamp;
    msg.header.frame_id = "camera";
    msg.query_id = static_cast<uint64_t>(second ? k - kFirstRun : k);
    if (k == 10) odom_pub.publish(odometry(stamp + ros::Duration(0.01), kNaN));
    if (k == 20) odom_pub.publish(odometry(stamp + ros::Duration(0.01), 1e300));
    if (k == 30) msg.header.stamp = stamp + ros::Duration(3600.0);
    if (k == 40) {
      LoopCandidate absurd = loopBehind(35, 5.0);
      absurd.relative_translation.z = -1e200;
      msg.candidates.push_back(absurd);
    }
    // The new run's keyframe j closes a loop with its keyframe j - 20 (20 m behind). The first run
    // also had a keyframe j - 20, 60 m further back: a back-end that keyed its graph by id alone
    // would join them.
    if (second && msg.query_id >= 25) msg.candidates.push_back(loopBehind(msg.query_id - 20, 20.0));
    loop_pub.publish(msg);
    rate.sleep();
  }
  odom_pub.publish(odometry(ros::Time::now() + ros::Duration(0.01), kFirstRun + kSecondRun));

  // The back-end publishes after its last change and reports every second.
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(20.0);
  std::map<std::string, std::string> status;
  while (ros::WallTime::now() < end) {
    status = latestStatus(diagnostics.messages());
    if (!status.empty() && count(status, "keyframes in graph") >= kFirstRun + kSecondRun - 1 &&
        count(status, "keyframes waiting") == 0) {
      break;
    }
    ros::WallDuration(0.2).sleep();
  }
  ASSERT_FALSE(status.empty()) << "no diagnostics from the back-end";
  EXPECT_EQ(count(status, "keyframes received"), static_cast<uint64_t>(kFirstRun + kSecondRun));
  EXPECT_EQ(count(status, "keyframes in graph"), static_cast<uint64_t>(kFirstRun + kSecondRun - 1));
  EXPECT_EQ(count(status, "dropped: future stamp"), 1u);
  EXPECT_EQ(count(status, "odometry rejected"), 2u);
  EXPECT_EQ(count(status, "loops refused"), 1u);
  EXPECT_EQ(count(status, "chains"), 2u) << "the reset starts a chain";
  EXPECT_EQ(count(status, "loops kept"), static_cast<uint64_t>(kSecondRun - 25));
  EXPECT_EQ(
      count(status, "keyframes received"),
      count(status, "keyframes in graph") + count(status, "keyframes waiting") + count(status, "keyframes dropped"));

  // The trajectory goes on after the reset, finite.
  ros::WallDuration(1.0).sleep();
  ASSERT_GT(trajectory.size(), 0u);
  const nav_msgs::Path last = trajectory.messages().back();
  EXPECT_EQ(last.poses.size(), static_cast<size_t>(kFirstRun + kSecondRun - 1));
  for (const auto& p : last.poses) {
    ASSERT_TRUE(std::isfinite(p.pose.position.x) && std::isfinite(p.pose.position.y));
  }
  EXPECT_NEAR(last.poses.back().pose.position.x, kFirstRun + kSecondRun - 1, 0.5);
  // Every loop edge drawn is 20 m long: none joins a keyframe of the new run to the first run's
  // keyframe of the same id (80 m).
  ASSERT_GT(edges.size(), 0u);
  size_t segments = 0;
  const visualization_msgs::MarkerArray drawn = edges.messages().back();  // a copy: messages() is a temporary
  for (const auto& marker : drawn.markers) {
    for (size_t i = 0; i + 1 < marker.points.size(); i += 2) {
      const double length =
          std::hypot(marker.points[i].x - marker.points[i + 1].x, marker.points[i].y - marker.points[i + 1].y);
      EXPECT_NEAR(length, 20.0, 0.5);
      ++segments;
    }
  }
  EXPECT_EQ(segments, static_cast<size_t>(kSecondRun - 25));
}

}  // namespace
}  // namespace mild_lcd::test

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_pose_graph_hostile");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
