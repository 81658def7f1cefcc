#include "mild_lcd/features/akaze_extractor.hpp"

#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

// AKAZE's descriptor samples a 20-sigma window; on thinner images no keypoint survives and the
// nonlinear scale space has nothing to build on.
constexpr int kMinSide = 32;

}  // namespace

AkazeExtractor::AkazeExtractor(const AkazeParams& params, double reference_pixels)
    : params_((params.validate(), params)), reference_pixels_(reference_pixels) {
  // The full M-LDB descriptor (size 0 = all 486 bits, 3 channels: intensity and both gradients).
  akaze_ = cv::AKAZE::create(cv::AKAZE::DESCRIPTOR_MLDB, 0, 3, static_cast<float>(params_.threshold), params_.octaves,
                             params_.octave_layers, cv::KAZE::DIFF_PM_G2);
}

Features AkazeExtractor::extract(const cv::Mat& image, PixelFormat format) const {
  const cv::Mat gray = toGray(image, format);
  return detectAndDescribe(*akaze_, gray, featureBudget(params_.num_features, gray.total(), reference_pixels_),
                           kMinSide, kDescriptorBytes, kName);
}

}  // namespace mild
