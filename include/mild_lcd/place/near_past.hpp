#pragma once

// The near-past band: a candidate policy (its parameters are detector/near_past*), applied by the
// database's query because it decides which keyframes take part in it. The database counts, for
// each keyframe below the candidate limit, the query features with a match in it; the policy turns
// those counts into the band.

#include <cstdint>
#include <vector>

#include "mild_lcd/common/types.hpp"

namespace mild {

// "The place I am still leaving": the newest keyframes before the candidate limit may still show
// what the query shows (far buildings in view while walking towards them), and would come out as a
// loop with the near past. The band is measured on the query itself: walking back from the newest
// eligible keyframe, it extends while the number of query features that have a match in the
// keyframe stays above the background level of the older keyframes,
//   median + kappa * 1.4826 MAD  of that count over the newest `background` eligible keyframes,
// allowing `tolerance` keyframes below it in a row. Keyframes in the band take no part in the query
// (neither votes nor N, N_f). A revisit is separated from the present by keyframes that look like
// neither: the band stops there. The band never reaches below `floor` (the start of the current
// session: older sessions are never "a moment ago", though they count as background); with fewer
// than `min_background` keyframes eligible, every one of the session is in the band (there is no
// background to tell the present from).
struct NearPastRule {
  double kappa = 2.0;
  int tolerance = 2;
  int min_background = 30;
  int background = 400;
  KeyframeIndex floor = 0;
};

// The band (how many of the newest keyframes below `limit` it removes) from matched[k], the query
// features with a match in keyframe k, for k < limit.
KeyframeIndex nearPastBand(const std::vector<uint32_t>& matched, KeyframeIndex limit, const NearPastRule& rule);

}  // namespace mild
