#include "mild_lcd/features/resolution_cap.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include <opencv2/imgproc.hpp>

namespace mild {

ResolutionCap::ResolutionCap(std::unique_ptr<FeatureExtractor> inner, double max_pixels)
    : inner_(std::move(inner)), max_pixels_(max_pixels) {}

Features ResolutionCap::extract(const cv::Mat& image, PixelFormat format) const {
  const double pixels = static_cast<double>(image.total());
  if (!(max_pixels_ > 0.0) || pixels <= max_pixels_) return inner_->extract(image, format);
  const double s = std::sqrt(max_pixels_ / pixels);
  const cv::Size shrunk(std::max(1, static_cast<int>(std::floor(image.cols * s))),
                        std::max(1, static_cast<int>(std::floor(image.rows * s))));
  cv::Mat small;
  cv::resize(image, small, shrunk, 0.0, 0.0, cv::INTER_AREA);
  Features out = inner_->extract(small, format);
  // Per axis, as the rounded size gives it; a pixel centre maps to a pixel centre.
  const double sx = static_cast<double>(image.cols) / shrunk.width;
  const double sy = static_cast<double>(image.rows) / shrunk.height;
  for (cv::KeyPoint& k : out.keypoints) {
    k.pt.x = static_cast<float>((k.pt.x + 0.5) * sx - 0.5);
    k.pt.y = static_cast<float>((k.pt.y + 0.5) * sy - 0.5);
    k.size = static_cast<float>(k.size * std::sqrt(sx * sy));
  }
  out.detection_scale = static_cast<float>(std::max(sx, sy));
  return out;
}

}  // namespace mild
