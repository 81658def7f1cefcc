#include "mild_lcd/features/orb_extractor.hpp"

#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

OrbExtractor::OrbExtractor(const OrbParams& params) : params_((params.validate(), params)) {
  orb_ = cv::ORB::create(params_.num_features, static_cast<float>(params_.scale_factor), params_.num_levels,
                         params_.edge_threshold, 0, 2, cv::ORB::HARRIS_SCORE, params_.edge_threshold,
                         params_.fast_threshold);
}

Features OrbExtractor::extract(const cv::Mat& image, PixelFormat format) const {
  // ORB keeps no keypoint within edge_threshold of the border, so a thinner image has none; and
  // OpenCV's pyramid fails on it (a level rounds to 0 pixels).
  return detectAndDescribe(*orb_, toGray(image, format), static_cast<size_t>(params_.num_features),
                           2 * params_.edge_threshold + 1, kDescriptorBytes, kName);
}

}  // namespace mild
