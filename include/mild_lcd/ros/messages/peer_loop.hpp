#pragma once

// What a station checks of a loop a peer decided for one of its keyframes before publishing it
// (docs/multi_robot.md, "What a station refuses"): a peer's message is never published as it came.
// The content is checked here; whether its query and candidates are keyframes this station stored
// and the peer announced is the station protocol's (mild::Station: it holds the maps and the ledger).

#include <cstddef>
#include <string>

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/TeamLoop.h"
#include "mild_lcd/team/team_messages.hpp"

namespace mild_lcd {

struct PeerLoopRules {
  std::string station;              // this station: the query's
  size_t max_candidates = 0;        // detector/max_candidates
  size_t max_correspondences = 0;   // ~max_keyframe_features: inliers of one pair, at most
  double decision_probability = 1;  // scoring/decision_probability
};

// Why `loop` cannot be published at this station as far as its own content tells, or "" when it
// can: the query must be this station's, every candidate the decider's, every number finite and in
// its range, at most max_candidates candidates and max_correspondences inliers each.
std::string peerLoopContentProblem(const mild_lcd::TeamLoop& loop, const PeerLoopRules& rules);

// The loop as this station publishes it: `accepted` decided here, as probability >=
// decision_probability for verified candidates only (a peer's word on it is not taken).
mild_lcd::LoopClosure::Ptr peerLoopAsPublished(const mild_lcd::TeamLoop& loop, const PeerLoopRules& rules);

// The loop as the station protocol takes it: its numbering, query and candidates, its content's
// problem ("" when none) and, as what is published when it is taken, peerLoopAsPublished
// (a mild_lcd::LoopClosure::ConstPtr).
mild::PeerLoop peerLoopFromMsg(const mild_lcd::TeamLoop& loop, const PeerLoopRules& rules);

}  // namespace mild_lcd
