#include "mild_lcd/features/orb_extractor.hpp"

#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

OrbExtractor::OrbExtractor(const OrbParams& params, double reference_pixels)
    : params_((params.validate(), params)), reference_pixels_(reference_pixels) {
  orb_ = cv::ORB::create(params_.num_features, static_cast<float>(params_.scale_factor), params_.num_levels,
                         params_.edge_threshold, 0, 2, cv::ORB::HARRIS_SCORE, params_.edge_threshold,
                         params_.fast_threshold);
}

Features OrbExtractor::extract(const cv::Mat& image, PixelFormat format) const {
  // ORB keeps no keypoint within edge_threshold of the border, so a thinner image has none; and
  // OpenCV's pyramid fails on it (a level rounds to 0 pixels).
  const cv::Mat gray = toGray(image, format);
  const size_t budget = featureBudget(params_.num_features, gray.total(), reference_pixels_);
  // OpenCV's ORB spreads its count over the pyramid levels, so it is set per image, not only capped.
  orb_->setMaxFeatures(static_cast<int>(budget));
  return detectAndDescribe(*orb_, gray, budget, 2 * params_.edge_threshold + 1, kDescriptorBytes, kName);
}

}  // namespace mild
