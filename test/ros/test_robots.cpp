// rostest node for a nodelet serving two robots (nodelet_robots.test): both replay their half of
// the embedded sample at the same time through the real `rosbag play`; every keyframe is answered on its
// robot's loop_closure and on loop_closures_all, nothing is dropped or rejected, and robot2's
// revisit of robot1's places is found as inter-robot loops.

#include <gtest/gtest.h>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/ros.h>

#include <future>
#include <set>

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/SparseMatch.h"
#include "mild_lcd/offline/evaluation.hpp"
#include "ros_test_support.hpp"

namespace mild_lcd::test {
namespace {

constexpr size_t kHalf = 150;  // sample frames per robot
const std::string kSampleDir = std::string(MILD_SOURCE_DIR) + "/sample/corridor";

// The latest values of mild_lcd's diagnostic status, waiting up to timeout_s for `key` to appear.
std::map<std::string, std::string> diagnostics(const std::string& key, double timeout_s) {
  TopicLog<diagnostic_msgs::DiagnosticArray> log("/diagnostics");
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout_s);
  std::map<std::string, std::string> values;
  while (ros::WallTime::now() < end && !values.count(key)) {
    for (const auto& array : log.messages()) {
      for (const auto& status : array.status) {
        if (status.name.find("loop closure detector") == std::string::npos) continue;
        for (const auto& kv : status.values) values[kv.key] = kv.value;
      }
    }
    ros::WallDuration(0.1).sleep();
  }
  return values;
}

TEST(Robots, TwoRobotsReplayingAtOnceFindTheirSharedPlaces) {
  TopicLog<mild_lcd::LoopClosure> robot1("/robot1/loop_closure"), robot2("/robot2/loop_closure"),
      all("/loop_closures_all");
  ASSERT_TRUE(robot1.waitForPublisher(30.0)) << "robot1/loop_closure was never advertised";
  ASSERT_TRUE(robot2.waitForPublisher(30.0));
  ASSERT_TRUE(all.waitForPublisher(30.0));
  const std::string bags = std::string(MILD_BAG_DIR) + "/sample_robot";
  auto play1 = std::async(std::launch::async, [&] { return playBag(bags + "1.bag", "/robot1/keyframe", "-r 4"); });
  auto play2 = std::async(std::launch::async, [&] { return playBag(bags + "2.bag", "/robot2/keyframe", "-r 4"); });
  ASSERT_EQ(play1.get(), 0) << "rosbag play of robot1 failed";
  ASSERT_EQ(play2.get(), 0) << "rosbag play of robot2 failed";
  ASSERT_TRUE(robot1.waitForCount(kHalf, 120.0)) << robot1.size() << " of robot1's keyframes answered";
  ASSERT_TRUE(robot2.waitForCount(kHalf, 120.0)) << robot2.size() << " of robot2's keyframes answered";
  ASSERT_TRUE(all.waitForCount(2 * kHalf, 10.0)) << all.size();
  ros::WallDuration(0.5).sleep();
  EXPECT_EQ(robot1.size(), kHalf) << "every keyframe answered once";
  EXPECT_EQ(robot2.size(), kHalf);
  EXPECT_EQ(all.size(), 2 * kHalf);

  // Answers name their robots; candidates name the map they are in (ids are the sample's frames).
  std::vector<mild::ScoredPair> inter;
  for (const auto& msg : robot1.messages()) {
    EXPECT_EQ(msg.query_robot, "robot1");
    EXPECT_LT(msg.query_id, kHalf);
    for (const auto& c : msg.candidates) EXPECT_EQ(c.robot == "robot1", c.id < kHalf) << c.robot << " " << c.id;
  }
  for (const auto& msg : robot2.messages()) {
    EXPECT_EQ(msg.query_robot, "robot2");
    EXPECT_GE(msg.query_id, kHalf);
    for (const auto& c : msg.candidates) {
      EXPECT_EQ(c.robot == "robot1", c.id < kHalf) << c.robot << " " << c.id;
      if (c.robot == "robot1" && c.verified) {
        inter.push_back({static_cast<int>(msg.query_id), static_cast<int>(c.id), c.probability});
      }
    }
  }
  // robot2's revisit of robot1's places: the ground truth's pairs from the second half to the first
  // whose robot1 keyframe was in the map when robot2's keyframe was queried. The two replays
  // interleave as the scheduler lets them (robot2's first frames see places robot1 reaches only
  // later), so only the pairs that could be found at all are scored; /loop_closures_all gives the
  // order the keyframes were processed in.
  std::map<int, size_t> processed_at;
  for (const auto& msg : all.messages()) processed_at.emplace(static_cast<int>(msg.query_id), processed_at.size());
  const auto findable = [&](const std::pair<int, int>& p) {
    return p.first >= static_cast<int>(kHalf) && p.second < static_cast<int>(kHalf) && processed_at.count(p.first) &&
           processed_at.count(p.second) && processed_at.at(p.second) < processed_at.at(p.first);
  };
  const mild::GroundTruth all_truth = mild::loadGroundTruth(kSampleDir + "/gt_loops.txt");
  mild::GroundTruth truth;
  for (const auto& p : all_truth.right) {
    if (findable(p)) {
      truth.right.insert(p);
      truth.loop_queries.insert(p.first);
    }
  }
  for (const auto& p : all_truth.dont_care) {
    if (findable(p)) truth.dont_care.insert(p);
  }
  RecordProperty("inter_robot_loop_queries", std::to_string(truth.loop_queries.size()));
  ASSERT_GE(truth.loop_queries.size(), 10u);
  const mild::Metrics m = mild::evaluate(truth, inter, 40);
  RecordProperty("inter_robot_recall_at_100p", std::to_string(m.recall_at_100_precision));
  RecordProperty("inter_robot_average_precision", std::to_string(m.average_precision));
  std::string best_wrong;  // names the false positive that caps recall@100%P when the check fails
  double best_wrong_score = -1.0;
  for (const auto& p : inter) {
    const std::pair<int, int> pair{p.query, p.candidate};
    if (!truth.right.count(pair) && !truth.dont_care.count(pair) && p.score > best_wrong_score) {
      best_wrong_score = p.score;
      best_wrong = std::to_string(p.query) + " -> " + std::to_string(p.candidate) + " at " + std::to_string(p.score);
    }
  }
  EXPECT_GE(m.recall_at_100_precision, 0.8)
      << "inter-robot loops of robot2 into robot1's map; highest wrong: " << best_wrong;

  // Nothing was dropped silently: every keyframe is counted as processed.
  const auto values = diagnostics("processed keyframes", 10.0);
  ASSERT_TRUE(values.count("processed keyframes"));
  EXPECT_EQ(values.at("processed keyframes"), std::to_string(2 * kHalf));
  EXPECT_EQ(values.at("dropped keyframes"), "0");
  EXPECT_EQ(values.at("rejected keyframes"), "0");
  EXPECT_EQ(values.at("robots"), "2");
  EXPECT_EQ(values.at("database keyframes"), std::to_string(2 * kHalf));
}

TEST(Robots, EachRobotsMapHasItsOwnServices) {
  for (const std::string robot : {"robot1", "robot2"}) {
    mild_lcd::SparseMatch srv;
    srv.request.query_id = robot == "robot1" ? 60 : 290;
    srv.request.train_id = robot == "robot1" ? 59 : 289;
    ASSERT_TRUE(ros::service::waitForService("/" + robot + "/sparse_match", ros::Duration(10.0)));
    ASSERT_TRUE(ros::service::call("/" + robot + "/sparse_match", srv));
    EXPECT_TRUE(srv.response.success) << robot << ": " << srv.response.message;
    // The other robot's ids are not in this robot's map.
    srv.request.query_id = robot == "robot1" ? 290 : 60;
    ASSERT_TRUE(ros::service::call("/" + robot + "/sparse_match", srv));
    EXPECT_FALSE(srv.response.success) << robot;
  }
  EXPECT_TRUE(ros::service::waitForService("/robot1/save_database", ros::Duration(5.0)));
  EXPECT_TRUE(ros::service::waitForService("/robot2/load_database", ros::Duration(5.0)));
  EXPECT_TRUE(ros::service::waitForService("/reset", ros::Duration(5.0)));
}

}  // namespace
}  // namespace mild_lcd::test
