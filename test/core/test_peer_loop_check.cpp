// test_peer_loop_check: what a station checks of a peer's loop before publishing it
// (team/peer_loop_check.hpp), on the protocol's plain structs: the rules themselves. That each
// TeamLoop field reaches them through the ROS conversion is test_ros_parts' PeerLoop.*.

#include <gtest/gtest.h>

#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "mild_lcd/team/peer_loop_check.hpp"

namespace mild {
namespace {

const PeerLoopRules kRules{"alpha", 3, 100, 0.909};

// bravo's loop for alpha's keyframe (robot1, session 1, id 42): one verified candidate at 0.95.
PeerLoop soundLoop() {
  PeerLoop loop;
  loop.decider = "bravo";
  loop.query = LoopKey{"alpha", "robot1", 1, 42, "bravo"};
  PeerLoop::Candidate c;
  c.station = "bravo";
  c.robot = "robot2";
  c.id = 5;
  c.probability = 0.95;
  c.verified = true;
  c.inliers = 40;
  c.matches = 80;
  c.inlier_ratio = 0.5;
  c.query_indices = c.candidate_indices = 40;
  c.query_pixels = c.candidate_pixels = 80;
  loop.candidates = {c};
  return loop;
}

TEST(PeerLoopCheck, ASoundLoopPasses) { EXPECT_EQ(peerLoopContentProblem(soundLoop(), kRules), ""); }

TEST(PeerLoopCheck, AcceptedIsVerifiedAtTheDecisionWhateverThePeerSaid) {
  PeerLoop::Candidate c = soundLoop().candidates[0];
  c.accepted = false;  // the peer's word is not read
  EXPECT_TRUE(acceptedHere(c, kRules));
  c.probability = 0.909;
  EXPECT_TRUE(acceptedHere(c, kRules)) << "at the decision: accepted";
  c.probability = 0.90;
  c.accepted = true;
  EXPECT_FALSE(acceptedHere(c, kRules)) << "below the decision";
  c.probability = 0.99;
  c.verified = false;
  EXPECT_FALSE(acceptedHere(c, kRules)) << "unverified";
  // A loop none of whose candidates is accepted here is not published at all.
  PeerLoop loop = soundLoop();
  loop.candidates[0].verified = false;
  loop.candidates[0].accepted = true;
  EXPECT_NE(peerLoopContentProblem(loop, kRules).find("no candidate is verified"), std::string::npos);
}

TEST(PeerLoopCheck, BoundsComeFromTheRules) {
  PeerLoop loop = soundLoop();
  loop.candidates.assign(3, loop.candidates[0]);
  EXPECT_EQ(peerLoopContentProblem(loop, kRules), "") << "max_candidates (3) candidates";
  loop.candidates.push_back(loop.candidates[0]);
  EXPECT_EQ(peerLoopContentProblem(loop, kRules), "4 candidates, more than detector/max_candidates (3)");
  loop = soundLoop();
  PeerLoop::Candidate& c = loop.candidates[0];
  c.query_indices = c.candidate_indices = 100;
  c.query_pixels = c.candidate_pixels = 200;
  EXPECT_EQ(peerLoopContentProblem(loop, kRules), "") << "max_correspondences (100) pairs";
  c.query_indices = c.candidate_indices = 101;
  c.query_pixels = c.candidate_pixels = 0;  // pixels are optional
  EXPECT_NE(peerLoopContentProblem(loop, kRules).find("too many"), std::string::npos);
  c.query_indices = c.candidate_indices = 10;
  c.candidate_pixels = 19;
  EXPECT_NE(peerLoopContentProblem(loop, kRules).find("do not pair up"), std::string::npos);
}

TEST(PeerLoopCheck, NonFiniteOrOutOfRangeValuesAreRefused) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<std::pair<std::string, std::function<void(PeerLoop&)>>> cases = {
      {"not this station's", [](PeerLoop& l) { l.query.station = "charlie"; }},
      {"frame id", [](PeerLoop& l) { l.frame_id_bytes = 300; }},
      {"no candidate", [](PeerLoop& l) { l.candidates.clear(); }},
      {"timings", [nan](PeerLoop& l) { l.timings[2] = nan; }},
      {"not the decider's", [](PeerLoop& l) { l.candidates[0].station = "alpha"; }},
      {"probability is not in [0, 1]", [](PeerLoop& l) { l.candidates[0].probability = 7.0; }},
      {"similarity", [nan](PeerLoop& l) { l.candidates[0].similarity = nan; }},
      {"above its matches", [](PeerLoop& l) { l.candidates[0].inliers = 81; }},
      {"relative pose is not finite", [nan](PeerLoop& l) { l.candidates[0].pose[3] = nan; }},
      {"correspondences are not finite", [](PeerLoop& l) { l.candidates[0].pixels_finite = false; }},
  };
  for (const auto& [reason, change] : cases) {
    PeerLoop loop = soundLoop();
    change(loop);
    const std::string problem = peerLoopContentProblem(loop, kRules);
    EXPECT_NE(problem.find(reason), std::string::npos) << "expected '" << reason << "', got '" << problem << "'";
  }
}

}  // namespace
}  // namespace mild
