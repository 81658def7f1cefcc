#include "mild_lcd/place/near_past.hpp"

#include <algorithm>
#include <cmath>

namespace mild {

KeyframeIndex nearPastBand(const std::vector<uint32_t>& matched, KeyframeIndex limit, const NearPastRule& rule) {
  const auto stored = static_cast<KeyframeIndex>(matched.size());
  limit = std::min(limit, stored);
  const KeyframeIndex floor = std::min(rule.floor, limit);
  if (limit == floor) return 0;
  // Without an exclusion window the newest keyframe is the present's nearest neighbour: the walk
  // starts from it.
  double valley = limit < stored ? *std::min_element(matched.begin() + limit, matched.end()) : matched[limit - 1];
  KeyframeIndex band = 0;
  for (KeyframeIndex k = limit; k-- > floor;) {
    // A count within its own spread of zero (valley <= rise^2) carries no view: the present's view
    // had faded before here, and what lies beyond shows neither place.
    if (valley <= rule.rise * rule.rise) break;
    const double spread = rule.rise * std::sqrt(valley);
    if (matched[k] > valley + spread) break;  // a place the present had left: a revisit, not the near past
    if (matched[k] < valley - spread) break;  // the present's view ends here at once: older keyframes are not it
    band = limit - k;
    valley = std::min<double>(valley, matched[k]);
  }
  return band;
}

}  // namespace mild
