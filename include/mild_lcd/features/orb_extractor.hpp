#pragma once

#include <opencv2/features2d.hpp>

#include "mild_lcd/features/feature_extractor.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

struct OrbParams {
  int num_features = 800;
  double scale_factor = 1.2;
  int num_levels = 8;
  int fast_threshold = 10;
  int edge_threshold = 31;

  static constexpr const char* kSection = "orb";
  static constexpr const char* kDoc = "ORB (OpenCV), features/type orb: 256-bit descriptors.";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("num_features", p.num_features, Bounds::atLeast(1),
      "Most ORB features kept per keyframe of features/reference_pixels pixels, strongest first (count, >= 1).");
    v("scale_factor", p.scale_factor, Bounds::aboveUpTo(1, 4),
      "Scale step between the levels of ORB's image pyramid (ratio, above 1 and up to 4).");
    v("num_levels", p.num_levels, Bounds::in(1, 32), "Levels of ORB's image pyramid (count, 1 to 32).");
    v("fast_threshold", p.fast_threshold, Bounds::in(1, 255), "FAST corner threshold of ORB (grey levels, 1 to 255).");
    v("edge_threshold", p.edge_threshold, Bounds::in(3, 255),
      "Border without features, also the descriptor's patch size (pixels, 3 to 255).");
  }
  void validate() const { validateDeclared(*this); }
};

// OpenCV ORB with the package's parameters: 256-bit (32-byte) descriptors. Not thread-safe
// (OpenCV's detector keeps state); use one per thread.
class OrbExtractor : public FeatureExtractor {
 public:
  using Params = OrbParams;
  static constexpr const char* kName = "orb";
  static constexpr int kDescriptorBytes = 32;

  // reference_pixels: num_features is meant for images of that many pixels (featureBudget); 0 = for any.
  explicit OrbExtractor(const OrbParams& params = {}, double reference_pixels = 0.0);
  const OrbParams& params() const { return params_; }

  const char* name() const override { return kName; }
  int descriptorBytes() const override { return kDescriptorBytes; }
  Features extract(const cv::Mat& image, PixelFormat format = PixelFormat::kGray) const override;

 private:
  OrbParams params_;
  double reference_pixels_ = 0.0;
  cv::Ptr<cv::ORB> orb_;
};

}  // namespace mild
