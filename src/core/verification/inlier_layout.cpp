#include "mild_lcd/verification/inlier_layout.hpp"

#include <algorithm>

#include <opencv2/calib3d.hpp>

namespace mild {

double inlierCoverage(const std::vector<cv::KeyPoint>& keypoints, const std::vector<cv::Point2f>& inliers) {
  if (keypoints.empty() || inliers.empty()) return 0.0;
  float x0 = keypoints[0].pt.x, y0 = keypoints[0].pt.y, x1 = x0, y1 = y0;
  for (const cv::KeyPoint& k : keypoints) {
    x0 = std::min(x0, k.pt.x), y0 = std::min(y0, k.pt.y);
    x1 = std::max(x1, k.pt.x), y1 = std::max(y1, k.pt.y);
  }
  constexpr int kColumns = 8, kRows = 6;
  const auto cell = [&](const cv::Point2f& p) {
    const int c = std::clamp(static_cast<int>((p.x - x0) / (x1 - x0 + 1e-3f) * kColumns), 0, kColumns - 1);
    const int r = std::clamp(static_cast<int>((p.y - y0) / (y1 - y0 + 1e-3f) * kRows), 0, kRows - 1);
    return r * kColumns + c;
  };
  std::vector<uint8_t> occupied(kColumns * kRows, 0), hit(kColumns * kRows, 0);
  for (const cv::KeyPoint& k : keypoints) occupied[cell(k.pt)] = 1;
  for (const cv::Point2f& p : inliers) hit[cell(p)] = 1;
  int cells = 0, covered = 0;
  for (int c = 0; c < kColumns * kRows; ++c) {
    cells += occupied[c];
    covered += occupied[c] && hit[c];
  }
  return cells > 0 ? static_cast<double>(covered) / cells : 0.0;
}

double homographyShare(const std::vector<cv::Point2f>& query_inliers, const std::vector<cv::Point2f>& train_inliers) {
  if (query_inliers.size() < 8 || query_inliers.size() != train_inliers.size()) return 0.0;
  cv::Mat mask;
  try {
    const cv::Mat h = cv::findHomography(query_inliers, train_inliers, cv::RANSAC, 3.0, mask);
    if (h.empty() || mask.empty()) return 0.0;
  } catch (const cv::Exception&) {
    return 0.0;  // degenerate (collinear points): no plane found
  }
  return static_cast<double>(cv::countNonZero(mask)) / static_cast<double>(query_inliers.size());
}

}  // namespace mild
