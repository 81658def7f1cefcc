#include "mild_lcd/features/brisk_extractor.hpp"

#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

// BRISK's sampling pattern reaches about 10 pixels (times pattern_scale) around a keypoint at its
// finest scale, so no keypoint survives nearer the border; thinner images are skipped before
// OpenCV's scale space sees them.
constexpr int kMinSide = 32;

}  // namespace

BriskExtractor::BriskExtractor(const BriskParams& params, double reference_pixels)
    : params_((params.validate(), params)), reference_pixels_(reference_pixels) {
  brisk_ = cv::BRISK::create(params_.threshold, params_.octaves, static_cast<float>(params_.pattern_scale));
}

Features BriskExtractor::extract(const cv::Mat& image, PixelFormat format) const {
  const int min_side = static_cast<int>(std::ceil(kMinSide * params_.pattern_scale));
  const cv::Mat gray = toGray(image, format);
  return detectAndDescribe(*brisk_, gray, featureBudget(params_.num_features, gray.total(), reference_pixels_),
                           min_side, kDescriptorBytes, kName);
}

}  // namespace mild
