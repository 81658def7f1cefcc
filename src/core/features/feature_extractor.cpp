#include "mild_lcd/features/feature_extractor.hpp"

#include <algorithm>
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

// OpenCV's ORB keeps every keypoint that ties with the weakest one it retains, so a tiled texture
// (thousands of equal responses) yields many times num_features. Keep exactly the strongest
// `limit`, ties broken by position so that the choice is deterministic.
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
  std::sort(order.begin(), order.end());  // keep OpenCV's order among the survivors
  std::vector<cv::KeyPoint> kept;
  cv::Mat rows(static_cast<int>(limit), descriptors.cols, descriptors.type());
  for (size_t i = 0; i < limit; ++i) {
    kept.push_back(keypoints[order[i]]);
    descriptors.row(order[i]).copyTo(rows.row(static_cast<int>(i)));
  }
  keypoints = std::move(kept);
  descriptors = rows;
}

}  // namespace

void OrbParams::validate() const {
  if (num_features < 1) throw InvalidInput("orb/num_features must be >= 1, got " + std::to_string(num_features));
  if (!(scale_factor > 1.0) || scale_factor > 4.0) {
    throw InvalidInput("orb/scale_factor must be in (1, 4], got " + std::to_string(scale_factor));
  }
  if (num_levels < 1 || num_levels > 32) {
    throw InvalidInput("orb/num_levels must be in [1, 32], got " + std::to_string(num_levels));
  }
  if (fast_threshold < 1 || fast_threshold > 255) {
    throw InvalidInput("orb/fast_threshold must be in [1, 255], got " + std::to_string(fast_threshold));
  }
  if (edge_threshold < 3 || edge_threshold > 255) {
    throw InvalidInput("orb/edge_threshold must be in [3, 255], got " + std::to_string(edge_threshold));
  }
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

OrbExtractor::OrbExtractor(const OrbParams& params) : params_((params.validate(), params)) {
  orb_ = cv::ORB::create(params_.num_features, static_cast<float>(params_.scale_factor), params_.num_levels,
                         params_.edge_threshold, 0, 2, cv::ORB::HARRIS_SCORE, params_.edge_threshold,
                         params_.fast_threshold);
}

Features OrbExtractor::extract(const cv::Mat& image, PixelFormat format) const {
  const cv::Mat gray = toGray(image, format);
  Features out;
  // ORB keeps no keypoint within edge_threshold of the border, so a thinner image has none; and
  // OpenCV's pyramid fails on it (a level rounds to 0 pixels).
  if (std::min(gray.cols, gray.rows) < 2 * params_.edge_threshold + 1) return out;
  cv::Mat descriptors;
  try {
    orb_->detectAndCompute(gray, cv::noArray(), out.keypoints, descriptors);
  } catch (const cv::Exception& e) {
    throw InvalidInput("ORB cannot process a " + std::to_string(gray.cols) + " x " + std::to_string(gray.rows) +
                       " image with these orb/ parameters: " + e.err);
  }
  if (descriptors.rows != static_cast<int>(out.keypoints.size())) return Features{};
  keepStrongest(out.keypoints, descriptors, static_cast<size_t>(params_.num_features));
  out.descriptors = descriptorsFromMat(descriptors);
  return out;
}

}  // namespace mild
