#include "mild_lcd/place/near_past.hpp"

#include <algorithm>
#include <cmath>

#include "mild_lcd/common/median.hpp"

namespace mild {

KeyframeIndex nearPastBand(const std::vector<uint32_t>& matched, KeyframeIndex limit, const NearPastRule& rule) {
  const KeyframeIndex floor = std::min(rule.floor, limit);
  const KeyframeIndex session = limit - floor;
  if (session == 0) return 0;
  // The background may include earlier sessions: they show elsewhere as well as anything does.
  if (limit < static_cast<KeyframeIndex>(rule.min_background)) return session;
  const KeyframeIndex window = std::min<KeyframeIndex>(limit, static_cast<KeyframeIndex>(std::max(1, rule.background)));
  std::vector<double> level(window);
  for (KeyframeIndex i = 0; i < window; ++i) level[i] = matched[limit - 1 - i];
  const double centre = upperMedian(level);
  for (double& v : level) v = std::abs(v - centre);
  const double threshold = centre + rule.kappa * 1.4826 * upperMedian(level);
  KeyframeIndex band = 0;
  int below = 0;
  for (KeyframeIndex k = limit; k-- > floor;) {
    if (matched[k] > threshold) {
      band = limit - k;
      below = 0;
    } else if (++below > rule.tolerance) {
      break;
    }
  }
  return band;
}

}  // namespace mild
