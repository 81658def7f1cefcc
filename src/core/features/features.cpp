#include "mild_lcd/features/features.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/imgproc.hpp>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

int channelsOf(PixelFormat f) {
  switch (f) {
    case PixelFormat::kGray:
      return 1;
    case PixelFormat::kBgr:
    case PixelFormat::kRgb:
      return 3;
    case PixelFormat::kBgra:
    case PixelFormat::kRgba:
      return 4;
  }
  return 0;
}

}  // namespace

std::optional<PixelFormat> decodedPixelFormat(int channels) {
  switch (channels) {
    case 1:
      return PixelFormat::kGray;
    case 3:
      return PixelFormat::kBgr;
    case 4:
      return PixelFormat::kBgra;
    default:
      return std::nullopt;
  }
}

void keepStrongest(std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors, size_t limit) {
  if (keypoints.size() <= limit) return;
  std::vector<int> order(keypoints.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    const cv::KeyPoint& ka = keypoints[a];
    const cv::KeyPoint& kb = keypoints[b];
    if (ka.response != kb.response) return ka.response > kb.response;
    if (ka.octave != kb.octave) return ka.octave < kb.octave;
    if (ka.pt.y != kb.pt.y) return ka.pt.y < kb.pt.y;
    return ka.pt.x < kb.pt.x;
  });
  order.resize(limit);
  std::sort(order.begin(), order.end());  // keep the detector's order among the survivors
  std::vector<cv::KeyPoint> kept;
  cv::Mat rows(static_cast<int>(limit), descriptors.cols, descriptors.type());
  for (size_t i = 0; i < limit; ++i) {
    kept.push_back(keypoints[order[i]]);
    descriptors.row(order[i]).copyTo(rows.row(static_cast<int>(i)));
  }
  keypoints = std::move(kept);
  descriptors = rows;
}

size_t featureBudget(int count, size_t pixels, double reference_pixels) {
  if (!(reference_pixels > 0.0)) return static_cast<size_t>(std::max(1, count));
  const double scale = std::min(4.0, std::sqrt(static_cast<double>(pixels) / reference_pixels));
  return static_cast<size_t>(std::max(1.0, std::round(count * scale)));
}

Features detectAndDescribe(cv::Feature2D& detector, const cv::Mat& gray, size_t limit, int min_side, int bytes,
                           const char* name) {
  Features out;
  if (std::min(gray.cols, gray.rows) < min_side) return out;
  cv::Mat descriptors;
  try {
    detector.detectAndCompute(gray, cv::noArray(), out.keypoints, descriptors);
  } catch (const cv::Exception& e) {
    throw InvalidInput(std::string(name) + " cannot process a " + std::to_string(gray.cols) + " x " +
                       std::to_string(gray.rows) + " image with these " + name + "/ parameters: " + e.err);
  }
  if (out.keypoints.empty() || descriptors.rows != static_cast<int>(out.keypoints.size())) return Features{};
  keepStrongest(out.keypoints, descriptors, limit);
  out.descriptors = descriptorsFromMat(descriptors, bytes);
  return out;
}

size_t depthsOutOfRange(const std::vector<float>& depths) {
  return static_cast<size_t>(std::count_if(depths.begin(), depths.end(),
                                           [](float z) { return std::isfinite(z) && z != 0.0f && !depthKnown(z); }));
}

void checkCameraAndDepths(const Features& features) {
  if (!features.depths.empty() && features.depths.size() != features.keypoints.size()) {
    throw InvalidInput("keyframe has " + std::to_string(features.depths.size()) + " depths for " +
                       std::to_string(features.keypoints.size()) + " keypoints (give one per keypoint, or none)");
  }
  if (!features.camera.wellFormed()) {
    throw InvalidInput("camera intrinsics need positive fx, fy and finite cx, cy (or all zero: unknown)");
  }
}

cv::Mat toGray(const cv::Mat& image, PixelFormat format) {
  if (image.empty()) throw InvalidInput("image is empty (0 x 0)");
  if (image.depth() != CV_8U) {
    throw InvalidInput("image must have 8 bits per channel, got " + cv::typeToString(image.type()));
  }
  if (image.channels() != channelsOf(format)) {
    throw InvalidInput("image has " + std::to_string(image.channels()) + " channel(s) but its encoding needs " +
                       std::to_string(channelsOf(format)));
  }
  cv::Mat gray;
  switch (format) {
    case PixelFormat::kGray:
      gray = image;
      break;
    case PixelFormat::kBgr:
      cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
      break;
    case PixelFormat::kRgb:
      cv::cvtColor(image, gray, cv::COLOR_RGB2GRAY);
      break;
    case PixelFormat::kBgra:
      cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
      break;
    case PixelFormat::kRgba:
      cv::cvtColor(image, gray, cv::COLOR_RGBA2GRAY);
      break;
  }
  return gray;
}

}  // namespace mild
