#pragma once

#include <opencv2/features2d.hpp>

#include "mild_lcd/features/feature_extractor.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

// BRISK (Leutenegger et al., ICCV 2011), the descriptor of OKVIS and maplab: 512 bits (64 bytes).
struct BriskParams {
  int num_features = 800;
  int threshold = 10;
  int octaves = 3;
  double pattern_scale = 1.0;

  static constexpr const char* kSection = "brisk";
  static constexpr const char* kDoc =
      "BRISK (OpenCV), features/type brisk: 512-bit descriptors, as OKVIS and maplab use.";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("num_features", p.num_features, Bounds::atLeast(1),
      "Most BRISK features kept per keyframe of features/reference_pixels pixels, strongest first (count, >= 1).");
    v("threshold", p.threshold, Bounds::in(1, 255), "AGAST detection threshold of BRISK (grey levels, 1 to 255).");
    v("octaves", p.octaves, Bounds::in(0, 8), "Scale-space octaves of BRISK (count, 0 to 8).");
    v("pattern_scale", p.pattern_scale, Bounds::in(0.25, 8), "Scale of BRISK's sampling pattern (factor, 0.25 to 8).");
  }
  void validate() const { validateDeclared(*this); }
};

// OpenCV BRISK with the package's parameters. Not thread-safe; use one per thread.
class BriskExtractor : public FeatureExtractor {
 public:
  using Params = BriskParams;
  static constexpr const char* kName = "brisk";
  static constexpr int kDescriptorBytes = 64;

  // reference_pixels: num_features is meant for images of that many pixels (featureBudget); 0 = for any.
  explicit BriskExtractor(const BriskParams& params = {}, double reference_pixels = 0.0);
  const BriskParams& params() const { return params_; }
  const char* name() const override { return kName; }
  int descriptorBytes() const override { return kDescriptorBytes; }
  Features extract(const cv::Mat& image, PixelFormat format = PixelFormat::kGray) const override;

 private:
  BriskParams params_;
  double reference_pixels_ = 0.0;
  cv::Ptr<cv::BRISK> brisk_;
};

}  // namespace mild
