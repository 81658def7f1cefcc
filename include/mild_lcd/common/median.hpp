#pragma once

// The two medians of the pipeline, in one place so that their difference is a choice, not an
// accident. Both reorder their argument (nth_element: O(n)).

#include <algorithm>
#include <vector>

namespace mild {

// The median, the two middle values averaged for an even count (the saliency's centre and MAD).
inline double median(std::vector<double>& v) {
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(mid), v.end());
  const double upper = v[mid];
  if (v.size() % 2 == 1) return upper;
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + static_cast<long>(mid)));
}

// The upper of the two middle values for an even count: for counts (the near-past band's matched
// features), where it stays one of the observed values; the band's near_past_kappa was chosen
// with it, so it is kept rather than averaged.
inline double upperMedian(std::vector<double>& v) {
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(mid), v.end());
  return v[mid];
}

}  // namespace mild
