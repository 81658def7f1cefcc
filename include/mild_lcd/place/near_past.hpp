#pragma once

// The near-past band: a candidate policy (its parameters are detector/near_past*), applied by the
// database's query because it decides which keyframes take part in it. The database counts, for
// every stored keyframe, the query features with a match in it; the policy turns those counts into
// the band.

#include <cstdint>
#include <vector>

#include "mild_lcd/common/types.hpp"

namespace mild {

// "The place I am still leaving": beyond the temporal exclusion, the newest eligible keyframes may
// still show what the query shows (far buildings in view while walking towards them, a slow camera
// at a high keyframe rate) and would come out as a loop with the near past. What tells the near
// past from a revisit is continuity with the present, measured on the query itself: the number of
// query features matched in a keyframe falls as the camera leaves a place, and the near past is
// reached from the query without that count ever rising again. A revisit is separated from the
// present by keyframes that show neither place, so its count rises out of that valley.
//
// Walking back from the newest eligible keyframe, the band goes on while the keyframe's count stays
// within `rise` x sqrt(valley) of the valley: the fewest matched in any keyframe between it and the
// query (the exclusion window, where the excluded keyframes still count, and the band so far). A
// count is a sum of chance events, so its spread grows as its square root. A count that rises
// beyond it is a revisit; one that falls beyond it at once is where the present's view ended, and
// a valley within its own spread of zero (at most rise^2) means it had ended already: keyframes that
// show neither place are not the near past either. Nothing here is counted
// in keyframes: at a high keyframe rate the view is continuous over the whole exclusion window and
// the band reaches as far back as the shared view; at a low one the view changes from keyframe to
// keyframe, the valley lies inside the window, and a revisit at the first eligible keyframe is a
// candidate at once. The band never reaches below `floor` (the start of the current session: older
// sessions are never "a moment ago").
struct NearPastRule {
  double rise = 4.0;  // detector/near_past_rise
  KeyframeIndex floor = 0;
};

// The band (how many of the newest keyframes below `limit` it removes) from matched[k], the query
// features with a match in stored keyframe k, for every stored keyframe (matched.size() of them,
// the query being the next); keyframes [limit, matched.size()) are the exclusion window.
KeyframeIndex nearPastBand(const std::vector<uint32_t>& matched, KeyframeIndex limit, const NearPastRule& rule);

}  // namespace mild
