#include "mild_lcd/ros/messages/peer_loop.hpp"

#include <cmath>

#include <ros/serialization.h>
#include <boost/make_shared.hpp>

namespace mild_lcd {
namespace {

constexpr size_t kMaxTextBytes = 256;  // a name or a frame id: far above any honest one

bool finite(double v) { return std::isfinite(v); }
bool share(double v) { return finite(v) && v >= 0.0 && v <= 1.0; }  // a probability or a ratio

std::string candidateProblem(const mild_lcd::LoopCandidate& c, const std::string& decider, const PeerLoopRules& rules) {
  if (c.station != decider)
    return "a candidate of station '" + c.station.substr(0, kMaxTextBytes) + "', not the decider's";
  if (c.robot.empty() || c.robot.size() > kMaxTextBytes) return "a candidate without a valid robot name";
  if (!share(c.probability) || !share(c.filter_probability)) return "a candidate's probability is not in [0, 1]";
  if (!finite(c.similarity) || c.similarity < 0.0) return "a candidate's similarity is not a finite value >= 0";
  if (!share(c.inlier_ratio) || !share(c.coverage) || !share(c.homography_share)) {
    return "a candidate's inlier ratio, coverage or homography share is not in [0, 1]";
  }
  if (c.inliers < 0 || c.matches < 0 || c.inliers > c.matches || c.pose_inliers < 0) {
    return "a candidate's inlier counts are negative or above its matches";
  }
  const auto& q = c.relative_rotation;
  const auto& t = c.relative_translation;
  if (!finite(q.x) || !finite(q.y) || !finite(q.z) || !finite(q.w) || !finite(t.x) || !finite(t.y) || !finite(t.z) ||
      !finite(c.reprojection_error) || c.reprojection_error < 0.0) {
    return "a candidate's relative pose is not finite";
  }
  const size_t pairs = c.inlier_query_indices.size();
  if (pairs > rules.max_correspondences || c.inlier_candidate_indices.size() != pairs ||
      (!c.inlier_query_pixels.empty() && c.inlier_query_pixels.size() != 2 * pairs) ||
      (!c.inlier_candidate_pixels.empty() && c.inlier_candidate_pixels.size() != 2 * pairs)) {
    return "a candidate's correspondences are too many or do not pair up";
  }
  for (const float v : c.inlier_query_pixels) {
    if (!finite(v)) return "a candidate's correspondences are not finite";
  }
  for (const float v : c.inlier_candidate_pixels) {
    if (!finite(v)) return "a candidate's correspondences are not finite";
  }
  return "";
}

}  // namespace

std::string peerLoopContentProblem(const mild_lcd::TeamLoop& loop, const PeerLoopRules& rules) {
  const mild_lcd::LoopClosure& l = loop.loop;
  if (l.query_station != rules.station) return "its query is not this station's";
  if (l.header.frame_id.size() > kMaxTextBytes) return "its frame id is longer than any camera's";
  if (l.candidates.empty()) return "no candidate";
  if (l.candidates.size() > rules.max_candidates) {
    return std::to_string(l.candidates.size()) + " candidates, more than detector/max_candidates (" +
           std::to_string(rules.max_candidates) + ")";
  }
  if (!finite(l.extract_ms) || !finite(l.query_ms) || !finite(l.filter_ms) || !finite(l.verify_ms)) {
    return "its timings are not finite";
  }
  for (const auto& c : l.candidates) {
    if (std::string why = candidateProblem(c, loop.decider, rules); !why.empty()) return why;
  }
  const mild_lcd::LoopClosure::Ptr published = peerLoopAsPublished(loop, rules);
  bool accepted = false;
  for (const auto& c : published->candidates) accepted = accepted || c.accepted;
  if (!accepted) return "no candidate is verified with probability >= scoring/decision_probability";
  return "";
}

mild_lcd::LoopClosure::Ptr peerLoopAsPublished(const mild_lcd::TeamLoop& loop, const PeerLoopRules& rules) {
  auto msg = boost::make_shared<mild_lcd::LoopClosure>(loop.loop);
  for (auto& c : msg->candidates) c.accepted = c.verified && c.probability >= rules.decision_probability;
  return msg;
}

mild::PeerLoop peerLoopFromMsg(const mild_lcd::TeamLoop& loop, const PeerLoopRules& rules) {
  mild::PeerLoop p;
  p.decider = loop.decider;
  p.epoch = loop.epoch;
  p.seq = loop.seq;
  const mild_lcd::LoopClosure& l = loop.loop;
  p.query = {l.query_station, l.query_robot, l.query_session, l.query_id, loop.decider};
  for (const auto& c : l.candidates) p.candidates.push_back({c.robot, c.session, c.id});
  p.content_problem = peerLoopContentProblem(loop, rules);
  if (p.content_problem.empty()) p.published = mild_lcd::LoopClosure::ConstPtr(peerLoopAsPublished(loop, rules));
  p.wire_bytes = ros::serialization::serializationLength(loop);
  return p;
}

}  // namespace mild_lcd
