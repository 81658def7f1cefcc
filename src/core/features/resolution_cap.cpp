#include "mild_lcd/features/resolution_cap.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include <opencv2/imgproc.hpp>

namespace mild {

ResolutionCap::ResolutionCap(std::unique_ptr<FeatureExtractor> inner, double max_pixels)
    : inner_(std::move(inner)), max_pixels_(max_pixels) {}

cv::Size ResolutionCap::shrunkSize(const cv::Size& frame, double max_pixels) {
  const double s = std::sqrt(max_pixels / (static_cast<double>(frame.width) * frame.height));
  int width = std::max(1, static_cast<int>(std::floor(frame.width * s)));
  int height = std::max(1, static_cast<int>(std::floor(frame.height * s)));
  // A side held at one pixel must not let the other keep more than the cap.
  const int longest = static_cast<int>(std::floor(max_pixels));
  if (height == 1) width = std::min(width, longest);
  if (width == 1) height = std::min(height, longest);
  return {width, height};
}

Features ResolutionCap::extract(const cv::Mat& image, PixelFormat format) const {
  const double pixels = static_cast<double>(image.total());
  if (!(max_pixels_ > 0.0) || pixels <= max_pixels_) return inner_->extract(image, format);
  // Grey first: the image's format is checked before anything else (InvalidInput), and a third of
  // the pixels are resized.
  const cv::Mat gray = toGray(image, format);
  const cv::Size shrunk = shrunkSize(gray.size(), max_pixels_);
  cv::Mat small;
  cv::resize(gray, small, shrunk, 0.0, 0.0, cv::INTER_AREA);
  Features out = inner_->extract(small, PixelFormat::kGray);
  // Per axis, as the rounded size gives it; INTER_AREA maps a pixel centre to a pixel centre.
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
