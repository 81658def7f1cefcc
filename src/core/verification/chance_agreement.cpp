#include "mild_lcd/verification/chance_agreement.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace mild {

namespace {

double log10Binomial(int n, int k) {
  return (std::lgamma(n + 1.0) - std::lgamma(k + 1.0) - std::lgamma(n - k + 1.0)) / std::log(10.0);
}

}  // namespace

double chanceInlierProbability(const std::vector<cv::KeyPoint>& keypoints, double tolerance_px) {
  if (keypoints.size() < 2 || !(tolerance_px > 0)) return 1.0;
  float min_x = std::numeric_limits<float>::max(), min_y = min_x;
  float max_x = std::numeric_limits<float>::lowest(), max_y = max_x;
  for (const cv::KeyPoint& k : keypoints) {
    if (!std::isfinite(k.pt.x) || !std::isfinite(k.pt.y)) continue;
    min_x = std::min(min_x, k.pt.x);
    max_x = std::max(max_x, k.pt.x);
    min_y = std::min(min_y, k.pt.y);
    max_y = std::max(max_y, k.pt.y);
  }
  const double width = static_cast<double>(max_x) - min_x, height = static_cast<double>(max_y) - min_y;
  if (!(width > 0) || !(height > 0)) return 1.0;
  const double p = 2.0 * tolerance_px * std::hypot(width, height) / (width * height);
  return std::clamp(p, 1e-9, 1.0);
}

double log10FalseAlarms(int matches, int inliers, double chance_probability, int sample_size) {
  if (inliers <= sample_size || matches <= sample_size) return 0.0;
  inliers = std::min(inliers, matches);
  const double p = std::clamp(chance_probability, 1e-9, 1.0);
  return std::log10(static_cast<double>(matches - sample_size)) + log10Binomial(matches, inliers) +
         log10Binomial(inliers, sample_size) + (inliers - sample_size) * std::log10(p);
}

}  // namespace mild
