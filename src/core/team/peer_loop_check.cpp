#include "mild_lcd/team/peer_loop_check.hpp"

#include <cmath>

namespace mild {
namespace {

constexpr size_t kMaxTextBytes = 256;  // a name or a frame id: far above any honest one

bool finite(double v) { return std::isfinite(v); }
bool share(double v) { return finite(v) && v >= 0.0 && v <= 1.0; }  // a probability or a ratio

std::string candidateProblem(const PeerLoop::Candidate& c, const std::string& decider, const PeerLoopRules& rules) {
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
  bool pose_finite = finite(c.reprojection_error) && c.reprojection_error >= 0.0;
  for (const double v : c.pose) pose_finite = pose_finite && finite(v);
  if (!pose_finite) return "a candidate's relative pose is not finite";
  const size_t pairs = c.query_indices;
  if (pairs > rules.max_correspondences || c.candidate_indices != pairs ||
      (c.query_pixels != 0 && c.query_pixels != 2 * pairs) ||
      (c.candidate_pixels != 0 && c.candidate_pixels != 2 * pairs)) {
    return "a candidate's correspondences are too many or do not pair up";
  }
  if (!c.pixels_finite) return "a candidate's correspondences are not finite";
  return "";
}

}  // namespace

bool acceptedHere(const PeerLoop::Candidate& c, const PeerLoopRules& rules) {
  return c.verified && c.probability >= rules.decision_probability;
}

std::string peerLoopContentProblem(const PeerLoop& loop, const PeerLoopRules& rules) {
  if (loop.query.station != rules.station) return "its query is not this station's";
  if (loop.frame_id_bytes > kMaxTextBytes) return "its frame id is longer than any camera's";
  if (loop.candidates.empty()) return "no candidate";
  if (loop.candidates.size() > rules.max_candidates) {
    return std::to_string(loop.candidates.size()) + " candidates, more than detector/max_candidates (" +
           std::to_string(rules.max_candidates) + ")";
  }
  for (const double ms : loop.timings) {
    if (!finite(ms)) return "its timings are not finite";
  }
  bool accepted = false;
  for (const PeerLoop::Candidate& c : loop.candidates) {
    if (std::string why = candidateProblem(c, loop.decider, rules); !why.empty()) return why;
    accepted = accepted || acceptedHere(c, rules);
  }
  if (!accepted) return "no candidate is verified with probability >= scoring/decision_probability";
  return "";
}

}  // namespace mild
