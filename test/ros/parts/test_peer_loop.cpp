// test_ros_parts: a team peer's loop from its message (ros/messages/team_conversions.hpp) to the
// station's check (team/peer_loop_check.hpp, test_peer_loop_check): each content a hostile or broken
// peer could send in a TeamLoop reaches the check and is refused with its reason, and what is
// published carries `accepted` as decided here, never as the peer sent it. Whether the query and the
// candidates are keyframes the station stored and the peer announced is mild::Station's
// (test_station_protocol).

#include <limits>

#include "mild_lcd/ros/messages/team_conversions.hpp"
#include "mild_lcd/team/peer_loop_check.hpp"
#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

const mild::PeerLoopRules kRules{"alpha", 10, 1000, 0.909};

// bravo's loop for alpha's keyframe (robot1, session 1, id 42): one verified candidate of bravo's
// robot2 at 0.95, sent with `accepted` false (this station decides it).
mild_lcd::TeamLoop soundLoop() {
  mild_lcd::TeamLoop loop;
  loop.decider = "bravo";
  loop.epoch = 3;
  loop.seq = 7;
  loop.loop.query_station = "alpha";
  loop.loop.query_robot = "robot1";
  loop.loop.query_session = 1;
  loop.loop.query_id = 42;
  mild_lcd::LoopCandidate c;
  c.station = "bravo";
  c.robot = "robot2";
  c.session = 0;
  c.id = 5;
  c.probability = 0.95;
  c.filter_probability = 0.8;
  c.similarity = 3.0;
  c.verified = true;
  c.inliers = 40;
  c.matches = 80;
  c.inlier_ratio = 0.5;
  c.coverage = 0.4;
  c.homography_share = 0.1;
  c.relative_rotation.w = 1.0;
  c.pose_inliers = 30;
  c.reprojection_error = 0.8;
  c.inlier_query_indices = {1, 2};
  c.inlier_candidate_indices = {3, 4};
  c.inlier_query_pixels = {1, 2, 3, 4};
  c.inlier_candidate_pixels = {5, 6, 7, 8};
  loop.loop.candidates = {c};
  return loop;
}

// The reason `change` gives soundLoop() for not being published ("" when it is published).
std::string problemAfter(const std::function<void(mild_lcd::TeamLoop&)>& change) {
  mild_lcd::TeamLoop loop = soundLoop();
  change(loop);
  return mild::peerLoopContentProblem(peerLoopFromMsg(loop), kRules);
}

// The loop as published once the station took it: `accepted` as decided here.
mild_lcd::LoopClosure::ConstPtr publishedAfterTaking(const mild_lcd::TeamLoop& loop) {
  mild::PeerLoop taken = peerLoopFromMsg(loop);
  for (mild::PeerLoop::Candidate& c : taken.candidates) c.accepted = mild::acceptedHere(c, kRules);
  return peerLoopToPublish(taken);
}

TEST(PeerLoop, ASoundLoopIsTakenWithItsNumberingQueryAndCandidates) {
  const mild::PeerLoop taken = peerLoopFromMsg(soundLoop());
  EXPECT_EQ(mild::peerLoopContentProblem(taken, kRules), "");
  EXPECT_EQ(taken.decider, "bravo");
  EXPECT_EQ(taken.epoch, 3u);
  EXPECT_EQ(taken.seq, 7u);
  EXPECT_EQ(taken.query.station, "alpha");
  EXPECT_EQ(taken.query.robot, "robot1");
  EXPECT_EQ(taken.query.session, 1u) << "the query's session as sent, not session 0";
  EXPECT_EQ(taken.query.id, 42u);
  ASSERT_EQ(taken.candidates.size(), 1u);
  EXPECT_EQ(taken.candidates[0].robot, "robot2");
  EXPECT_EQ(taken.candidates[0].id, 5u);
  EXPECT_GT(taken.wire_bytes, 0u);
  const auto published = publishedAfterTaking(soundLoop());
  ASSERT_EQ(published->candidates.size(), 1u);
  EXPECT_EQ(published->query_id, 42u);
  EXPECT_EQ(published->candidates[0].inlier_candidate_pixels, soundLoop().loop.candidates[0].inlier_candidate_pixels);
  EXPECT_TRUE(published->candidates[0].accepted) << "verified at 0.95 >= 0.909: accepted here";
}

TEST(PeerLoop, AcceptedIsDecidedHereNeverTakenFromThePeer) {
  mild_lcd::TeamLoop loop = soundLoop();
  mild_lcd::LoopCandidate unverified = loop.loop.candidates[0];
  unverified.verified = false;
  unverified.accepted = true;  // the peer's word
  unverified.id = 6;
  mild_lcd::LoopCandidate low = loop.loop.candidates[0];
  low.probability = 0.5;
  low.accepted = true;
  low.id = 7;
  loop.loop.candidates = {loop.loop.candidates[0], unverified, low};
  const mild_lcd::LoopClosure::ConstPtr published = publishedAfterTaking(loop);
  EXPECT_TRUE(published->candidates[0].accepted);
  EXPECT_FALSE(published->candidates[1].accepted) << "an unverified candidate marked accepted";
  EXPECT_FALSE(published->candidates[2].accepted) << "a probability below scoring/decision_probability";
  // With no candidate accepted here, the loop is not published at all.
  loop.loop.candidates = {unverified, low};
  EXPECT_NE(mild::peerLoopContentProblem(peerLoopFromMsg(loop), kRules).find("no candidate is verified"),
            std::string::npos);
}

TEST(PeerLoop, EachContentAPeerCouldBreakIsRefusedWithItsReason) {
  using L = mild_lcd::TeamLoop;
  const std::vector<std::pair<std::string, std::function<void(L&)>>> cases = {
      {"not this station's", [](L& l) { l.loop.query_station = "charlie"; }},
      {"frame id", [](L& l) { l.loop.header.frame_id.assign(300, 'x'); }},
      {"no candidate", [](L& l) { l.loop.candidates.clear(); }},
      {"15000 candidates, more than detector/max_candidates (10)",
       [](L& l) { l.loop.candidates.assign(15000, l.loop.candidates[0]); }},
      {"timings", [](L& l) { l.loop.extract_ms = kNaN; }},
      {"timings", [](L& l) { l.loop.query_ms = kInf; }},
      {"timings", [](L& l) { l.loop.filter_ms = kNaN; }},
      {"timings", [](L& l) { l.loop.verify_ms = kNaN; }},
      {"not the decider's", [](L& l) { l.loop.candidates[0].station = "alpha"; }},
      {"robot name", [](L& l) { l.loop.candidates[0].robot.clear(); }},
      {"probability is not in [0, 1]", [](L& l) { l.loop.candidates[0].probability = kNaN; }},
      {"probability is not in [0, 1]", [](L& l) { l.loop.candidates[0].probability = 7.0; }},
      {"probability is not in [0, 1]", [](L& l) { l.loop.candidates[0].filter_probability = -0.1; }},
      {"similarity", [](L& l) { l.loop.candidates[0].similarity = -1.0; }},
      {"inlier ratio", [](L& l) { l.loop.candidates[0].inlier_ratio = 1.5; }},
      {"inlier ratio", [](L& l) { l.loop.candidates[0].coverage = 1.5; }},
      {"inlier ratio", [](L& l) { l.loop.candidates[0].homography_share = -0.1; }},
      {"negative", [](L& l) { l.loop.candidates[0].matches = -1; }},
      {"negative", [](L& l) { l.loop.candidates[0].inliers = -1; }},
      {"above its matches", [](L& l) { l.loop.candidates[0].inliers = 81; }},
      {"negative", [](L& l) { l.loop.candidates[0].pose_inliers = -1; }},
      {"relative pose is not finite", [](L& l) { l.loop.candidates[0].relative_translation.x = kInf; }},
      {"relative pose is not finite", [](L& l) { l.loop.candidates[0].relative_translation.y = kNaN; }},
      {"relative pose is not finite", [](L& l) { l.loop.candidates[0].relative_translation.z = -kInf; }},
      {"relative pose is not finite", [](L& l) { l.loop.candidates[0].relative_rotation.x = kNaN; }},
      {"relative pose is not finite", [](L& l) { l.loop.candidates[0].relative_rotation.y = kInf; }},
      {"relative pose is not finite", [](L& l) { l.loop.candidates[0].relative_rotation.z = kNaN; }},
      {"relative pose is not finite", [](L& l) { l.loop.candidates[0].relative_rotation.w = kNaN; }},
      {"relative pose is not finite", [](L& l) { l.loop.candidates[0].reprojection_error = -1.0; }},
      {"do not pair up", [](L& l) { l.loop.candidates[0].inlier_candidate_indices.pop_back(); }},
      {"do not pair up", [](L& l) { l.loop.candidates[0].inlier_query_pixels.pop_back(); }},
      {"too many",
       [](L& l) {
         l.loop.candidates[0].inlier_query_indices.assign(1001, 0);
         l.loop.candidates[0].inlier_candidate_indices.assign(1001, 0);
         l.loop.candidates[0].inlier_query_pixels.clear();
         l.loop.candidates[0].inlier_candidate_pixels.clear();
       }},
      {"correspondences are not finite",
       [](L& l) { l.loop.candidates[0].inlier_candidate_pixels[1] = static_cast<float>(kNaN); }},
      {"correspondences are not finite",
       [](L& l) { l.loop.candidates[0].inlier_query_pixels[2] = static_cast<float>(kInf); }},
      {"do not pair up", [](L& l) { l.loop.candidates[0].inlier_query_indices.push_back(9); }},
  };
  for (const auto& [reason, change] : cases) {
    const std::string problem = problemAfter(change);
    EXPECT_NE(problem.find(reason), std::string::npos) << "expected '" << reason << "', got '" << problem << "'";
  }
  EXPECT_EQ(problemAfter([](L&) {}), "");
}

}  // namespace
}  // namespace mild_lcd
