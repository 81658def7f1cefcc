#pragma once

// The median of the pipeline (the saliency's centre and MAD). It reorders its argument
// (nth_element: O(n)).

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

}  // namespace mild
