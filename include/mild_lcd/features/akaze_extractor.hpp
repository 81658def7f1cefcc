#pragma once

#include <opencv2/features2d.hpp>

#include "mild_lcd/features/feature_extractor.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

// AKAZE (Alcantarilla et al., BMVC 2013) with its binary M-LDB descriptor: 486 bits in 61 bytes
// (the last two bits are always zero). Slower to extract than ORB or BRISK (a nonlinear scale
// space), more repeatable under blur.
struct AkazeParams {
  int num_features = 800;
  double threshold = 0.0001;
  int octaves = 4;
  int octave_layers = 4;

  static constexpr const char* kSection = "akaze";
  static constexpr const char* kDoc =
      "AKAZE with its M-LDB descriptor (OpenCV), features/type akaze: 486 bits in 61 bytes.";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("num_features", p.num_features, Bounds::atLeast(1),
      "Most AKAZE features kept per keyframe of features/reference_pixels pixels, strongest first (count, >= 1).");
    v("threshold", p.threshold, Bounds::between(0, 1),
      "AKAZE's detector response threshold (response units, above 0 and below 1).");
    v("octaves", p.octaves, Bounds::in(1, 8), "Scale-space octaves of AKAZE (count, 1 to 8).");
    v("octave_layers", p.octave_layers, Bounds::in(1, 8), "Sub-levels per octave of AKAZE (count, 1 to 8).");
  }
  void validate() const { validateDeclared(*this); }
};

// OpenCV AKAZE with the package's parameters. Not thread-safe; use one per thread.
class AkazeExtractor : public FeatureExtractor {
 public:
  using Params = AkazeParams;
  static constexpr const char* kName = "akaze";
  static constexpr int kDescriptorBytes = 61;

  // reference_pixels: num_features is meant for images of that many pixels (featureBudget); 0 = for any.
  explicit AkazeExtractor(const AkazeParams& params = {}, double reference_pixels = 0.0);
  const AkazeParams& params() const { return params_; }
  const char* name() const override { return kName; }
  int descriptorBytes() const override { return kDescriptorBytes; }
  Features extract(const cv::Mat& image, PixelFormat format = PixelFormat::kGray) const override;

 private:
  AkazeParams params_;
  double reference_pixels_ = 0.0;
  cv::Ptr<cv::AKAZE> akaze_;
};

}  // namespace mild
