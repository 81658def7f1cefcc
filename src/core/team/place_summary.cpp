#include "mild_lcd/team/place_summary.hpp"

#include <algorithm>
#include <numeric>

namespace mild {

DescriptorList strongestDescriptors(const Features& features, size_t count) {
  const size_t n = features.descriptors.size();
  if (count >= n) return features.descriptors;
  std::vector<size_t> order(n);
  std::iota(order.begin(), order.end(), size_t{0});
  const auto response = [&](size_t i) { return i < features.keypoints.size() ? features.keypoints[i].response : 0.f; };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return response(a) > response(b); });
  order.resize(count);
  std::sort(order.begin(), order.end());  // the keyframe's order: the same summary whatever sorted it
  DescriptorList strongest;
  strongest.reserve(count);
  for (size_t i : order) strongest.push_back(features.descriptors[i]);
  return strongest;
}

size_t descriptorsWithin(size_t budget_bytes, int bytes) {
  if (bytes <= 0) return 1;
  return std::max<size_t>(1, budget_bytes / static_cast<size_t>(bytes));
}

}  // namespace mild
