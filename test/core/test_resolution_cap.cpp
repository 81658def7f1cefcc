// features/max_pixels: frames larger than the cap are shrunk before extraction, their keypoints
// mapped back to the frame's pixels, and verification widens its tolerances by the shrink
// (resolution_cap.hpp, Features::detection_scale).
#include <gtest/gtest.h>

#include <algorithm>

#include <opencv2/imgproc.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"
#include "test_images.hpp"

namespace mild {
namespace {

cv::Mat enlarged(const cv::Mat& frame, double factor) {
  cv::Mat out;
  cv::resize(frame, out, cv::Size(), factor, factor, cv::INTER_CUBIC);
  return out;
}

FeatureParams capped(const char* type, double max_pixels) {
  FeatureParams params;
  params.type = type;
  params.max_pixels = max_pixels;
  return params;
}

TEST(ResolutionCap, AFrameWithinTheCapIsExtractedAsItIs) {
  const cv::Mat& frame = test::sampleFrames().at(30);  // 320 x 240
  const Features plain = makeFeatureExtractor(capped("orb", 0.0))->extract(frame, PixelFormat::kGray);
  const Features within = makeFeatureExtractor(capped("orb", 320.0 * 240.0))->extract(frame, PixelFormat::kGray);
  ASSERT_EQ(plain.keypoints.size(), within.keypoints.size());
  for (size_t i = 0; i < plain.keypoints.size(); ++i) EXPECT_EQ(plain.keypoints[i].pt, within.keypoints[i].pt);
  EXPECT_EQ(within.detection_scale, 1.0f);
}

// A 1280 x 960 frame under a 320 x 240 cap costs what 320 x 240 costs: the budget of 320 x 240,
// keypoints spread over the whole frame in its own pixels, detection_scale 4.
TEST(ResolutionCap, ALargerFrameIsShrunkAndItsKeypointsMappedBack) {
  const cv::Mat large = enlarged(test::sampleFrames().at(30), 4.0);
  for (const char* type : {"orb", "brisk", "akaze"}) {
    const Features f = makeFeatureExtractor(capped(type, 320.0 * 240.0))->extract(large, PixelFormat::kGray);
    ASSERT_GT(f.keypoints.size(), 100u) << type;
    EXPECT_LE(f.keypoints.size(), 800u) << type << ": the budget of the shrunk size, not 4 x 800";
    EXPECT_FLOAT_EQ(f.detection_scale, 4.0f) << type;
    float max_x = 0.0f, max_y = 0.0f;
    for (const cv::KeyPoint& k : f.keypoints) {
      max_x = std::max(max_x, k.pt.x);
      max_y = std::max(max_y, k.pt.y);
      EXPECT_GE(k.pt.x, 0.0f);
      EXPECT_GE(k.pt.y, 0.0f);
    }
    EXPECT_GT(max_x, 1000.0f) << type << ": positions are the frame's pixels";
    EXPECT_LT(max_x, 1280.0f) << type;
    EXPECT_GT(max_y, 700.0f) << type;
    EXPECT_LT(max_y, 960.0f) << type;
  }
}

// Two views of one place, at 1280 x 960 under a 320 x 240 cap, verify as well as at 320 x 240:
// the 1-pixel tolerance is 4 of the frame's pixels for keypoints found at a quarter of its size.
// Without the widening (detection_scale 1) the same keypoints keep fewer inliers.
TEST(ResolutionCap, VerificationWidensItsToleranceByTheShrink) {
  const cv::Mat& a = test::sampleFrames().at(30);
  const cv::Mat& b = test::sampleFrames().at(33);
  const GeometricVerifier verifier{VerificationParams{}};
  const auto extractor_small = makeFeatureExtractor(capped("orb", 0.0));
  const int small =
      verifier.verify(extractor_small->extract(a, PixelFormat::kGray), extractor_small->extract(b, PixelFormat::kGray))
          .inliers;
  const auto extractor_capped = makeFeatureExtractor(capped("orb", 320.0 * 240.0));
  Features qa = extractor_capped->extract(enlarged(a, 4.0), PixelFormat::kGray);
  Features qb = extractor_capped->extract(enlarged(b, 4.0), PixelFormat::kGray);
  const int widened = verifier.verify(qa, qb).inliers;
  qa.detection_scale = qb.detection_scale = 1.0f;
  const int unwidened = verifier.verify(qa, qb).inliers;
  ASSERT_GE(small, 40);
  EXPECT_GE(widened, small * 0.8) << "capped " << widened << ", 320 x 240 " << small;
  EXPECT_LT(unwidened, widened * 0.8) << "a quarter-size keypoint is not placed within 1 frame pixel";
}

// A frame a pixel thin shrinks to nothing a detector can use: no features, no failure.
TEST(ResolutionCap, AThinFrameYieldsNoFeaturesAndNoError) {
  const cv::Mat thin(1, 200000, CV_8UC1, cv::Scalar(128));
  for (const char* type : {"orb", "brisk", "akaze"}) {
    Features f;
    EXPECT_NO_THROW(f = makeFeatureExtractor(capped(type, 4096.0))->extract(thin, PixelFormat::kGray)) << type;
    EXPECT_TRUE(f.keypoints.empty()) << type;
  }
}

TEST(ResolutionCap, ACapBelow64By64IsRefused) {
  EXPECT_THROW(makeFeatureExtractor(capped("orb", 1000.0)), InvalidInput);
  EXPECT_THROW(makeFeatureExtractor(capped("orb", -1.0)), InvalidInput);
  EXPECT_NO_THROW(makeFeatureExtractor(capped("orb", 4096.0)));
}

}  // namespace
}  // namespace mild
