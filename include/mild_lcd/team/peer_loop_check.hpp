#pragma once

// What a station checks of a loop a peer decided for one of its keyframes before publishing it
// (docs/multi_robot.md, "What a station refuses"): a peer's message is never published as it came.
// This is what the loop's own content tells; whether its query and candidates are keyframes this
// station stored and the peer announced is Station's (it holds the maps and the ledger).

#include <cstddef>
#include <string>

#include "mild_lcd/team/team_messages.hpp"

namespace mild {

struct PeerLoopRules {
  std::string station;              // this station: the query's
  size_t max_candidates = 0;        // detector/max_candidates
  size_t max_correspondences = 0;   // ~max_keyframe_features: inliers of one pair, at most
  double decision_probability = 1;  // scoring/decision_probability
};

// Whether this station accepts the candidate: verified and probability >= decision_probability (a
// peer's word on it is not taken).
bool acceptedHere(const PeerLoop::Candidate& candidate, const PeerLoopRules& rules);

// Why `loop` cannot be published at this station as far as its own content tells, or "" when it
// can: the query must be this station's, every candidate the decider's, every number finite and in
// its range, at most max_candidates candidates and max_correspondences inliers each, and one
// candidate accepted here.
std::string peerLoopContentProblem(const PeerLoop& loop, const PeerLoopRules& rules);

}  // namespace mild
