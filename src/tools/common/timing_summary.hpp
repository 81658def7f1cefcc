#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

namespace mild::tools {

struct TimingSummary {
  double mean = 0.0;
  double median = 0.0;
  double p95 = 0.0;
  double p99 = 0.0;
  double max = 0.0;
};

// Nearest-rank percentile on a copy of the samples.
inline double percentile(std::vector<double> samples, double q) {
  if (samples.empty()) return 0.0;
  std::sort(samples.begin(), samples.end());
  const size_t rank = static_cast<size_t>(std::ceil(q * static_cast<double>(samples.size())));
  return samples[std::min(samples.size() - 1, rank == 0 ? 0 : rank - 1)];
}

inline TimingSummary summarize(const std::vector<double>& samples) {
  TimingSummary s;
  if (samples.empty()) return s;
  for (double v : samples) s.mean += v;
  s.mean /= static_cast<double>(samples.size());
  s.median = percentile(samples, 0.5);
  s.p95 = percentile(samples, 0.95);
  s.p99 = percentile(samples, 0.99);
  s.max = *std::max_element(samples.begin(), samples.end());
  return s;
}

}  // namespace mild::tools
