// rostest (nodelet_tuning.test): live tuning through dynamic_reconfigure's own service, against a
// nodelet started from the fixture's YAML, then a replay of the fixture bag under the new values.

#include <gtest/gtest.h>

#include <dynamic_reconfigure/Reconfigure.h>
#include <ros/ros.h>

#include "../common/run_command.hpp"
#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/SparseMatch.h"
#include "ros_test_support.hpp"

namespace mild_lcd::test {
namespace {

const std::string kBag = std::string(MILD_BAG_DIR) + "/fixture_corridor.bag";

dynamic_reconfigure::Config reconfigure(const dynamic_reconfigure::Config& change) {
  dynamic_reconfigure::Reconfigure srv;
  srv.request.config = change;
  EXPECT_TRUE(ros::service::waitForService("/mild_lcd/tuning/set_parameters", ros::Duration(20.0)));
  EXPECT_TRUE(ros::service::call("/mild_lcd/tuning/set_parameters", srv));
  return srv.response.config;
}

template <class Value>
Value valueOf(const std::vector<Value>& values, const std::string& name) {
  for (const Value& v : values)
    if (v.name == name) return v;
  ADD_FAILURE() << name << " missing from the configuration";
  return {};
}

TEST(Tuning, StartsFromTheNodesValuesAndAppliesChangesBetweenKeyframes) {
  // The YAML's exclusion (8 fixture keyframes), not the cfg's default (40). An empty request is
  // dynamic_reconfigure's "get": its answer waits until the server holds the node's values.
  EXPECT_EQ(valueOf(reconfigure({}).ints, "detector_exclusion_frames").value, 8);
  int exclusion = 0;
  EXPECT_TRUE(ros::param::get("/mild_lcd/tuning/detector_exclusion_frames", exclusion));
  EXPECT_EQ(exclusion, 8);

  dynamic_reconfigure::Config change;
  dynamic_reconfigure::IntParameter candidates;
  candidates.name = "detector_max_candidates";
  candidates.value = 1;
  change.ints.push_back(candidates);
  dynamic_reconfigure::DoubleParameter decision;
  decision.name = "scoring_decision_probability";
  decision.value = 0.9;
  change.doubles.push_back(decision);
  const dynamic_reconfigure::Config now = reconfigure(change);
  EXPECT_EQ(valueOf(now.ints, "detector_max_candidates").value, 1);
  EXPECT_EQ(valueOf(now.doubles, "scoring_decision_probability").value, 0.9);
  EXPECT_EQ(valueOf(now.ints, "detector_exclusion_frames").value, 8) << "what was not named stays";

  // Out of range: dynamic_reconfigure keeps it within the cfg's bounds, which the detector accepts.
  // From 2, so that only the clamp to the lower bound (1) gives 1.
  change.doubles.clear();
  change.ints[0].value = 2;
  ASSERT_EQ(valueOf(reconfigure(change).ints, "detector_max_candidates").value, 2);
  change.ints[0].value = 2147483647;  // each candidate is verified: the count is bounded
  EXPECT_EQ(valueOf(reconfigure(change).ints, "detector_max_candidates").value, 100) << "clamped to the cfg's maximum";
  change.ints[0].value = 0;
  EXPECT_EQ(valueOf(reconfigure(change).ints, "detector_max_candidates").value, 1) << "clamped to the cfg's minimum";

  TopicLog<mild_lcd::LoopClosure> outputs("/loop_closure");
  ASSERT_TRUE(outputs.waitForPublisher(20.0));
  ASSERT_EQ(playBag(kBag, "/camera/keyframe", "-r 4"), 0);
  ASSERT_TRUE(outputs.waitForCount(60, 120.0));
  size_t accepted = 0;
  for (const auto& msg : outputs.messages()) {
    EXPECT_LE(msg.candidates.size(), 1u) << "keyframe " << msg.query_id;
    for (const auto& c : msg.candidates) {
      EXPECT_EQ(c.accepted, c.verified && c.probability >= 0.9) << "keyframe " << msg.query_id;
      accepted += c.accepted ? 1 : 0;
    }
  }
  EXPECT_GT(accepted, 0u) << "the revisit still closes loops";

  // The sparse_match service follows a retune of the verification too.
  mild_lcd::SparseMatch srv;
  srv.request.query_id = 159;  // fixture keyframes 59 and 9 (ids from 100): a loop
  srv.request.train_id = 109;
  ASSERT_TRUE(ros::service::call("/sparse_match", srv));
  ASSERT_TRUE(srv.response.success) << srv.response.message;
  EXPECT_TRUE(srv.response.verified);
  const int inliers = srv.response.inliers;
  dynamic_reconfigure::Config strict;
  dynamic_reconfigure::IntParameter min_inliers;
  min_inliers.name = "verification_min_inliers";
  min_inliers.value = inliers + 1;
  strict.ints.push_back(min_inliers);
  EXPECT_EQ(valueOf(reconfigure(strict).ints, "verification_min_inliers").value, inliers + 1);
  ASSERT_TRUE(ros::service::call("/sparse_match", srv));
  EXPECT_EQ(srv.response.inliers, inliers);
  EXPECT_FALSE(srv.response.verified) << "one inlier short of the retuned min_inliers";
}

// dynamic_reconfigure's own server skipped entries that name no parameter or give one a value of
// another type, and applied the rest without a word. A request with such an entry is refused whole
// (the node logs which entries); a proper one after it is applied. dynparam, which reads the
// descriptions to type its values, works as with dynamic_reconfigure's server.
TEST(Tuning, ARequestWithAnUnknownOrMistypedEntryIsRefusedWhole) {
  const int before = valueOf(reconfigure({}).ints, "detector_max_candidates").value;
  const int wanted = before == 2 ? 3 : 2;
  dynamic_reconfigure::Config change;
  dynamic_reconfigure::IntParameter candidates;
  candidates.name = "detector_max_candidates";
  candidates.value = wanted;
  change.ints.push_back(candidates);
  dynamic_reconfigure::DoubleParameter typo;
  typo.name = "detector_max_candidatez";
  typo.value = 1.0;
  change.doubles.push_back(typo);
  EXPECT_EQ(valueOf(reconfigure(change).ints, "detector_max_candidates").value, before) << "an unknown name";
  change.doubles[0].name = "scoring_decision_probability";
  change.ints.push_back(candidates);
  change.ints.back().name = "verification_ratio";  // a double parameter given as an int
  EXPECT_EQ(valueOf(reconfigure(change).ints, "detector_max_candidates").value, before) << "a wrong type";
  change.ints.pop_back();
  change.doubles.clear();
  EXPECT_EQ(valueOf(reconfigure(change).ints, "detector_max_candidates").value, wanted) << "a proper request";

  const auto dynparam = mild::test::runCommand(
      "PATH=/usr/bin:$PATH rosrun dynamic_reconfigure dynparam set /mild_lcd/tuning detector_max_candidates " +
      std::to_string(before));
  EXPECT_EQ(dynparam.status, 0) << dynparam.output;
  EXPECT_EQ(valueOf(reconfigure({}).ints, "detector_max_candidates").value, before) << dynparam.output;
}

}  // namespace
}  // namespace mild_lcd::test
