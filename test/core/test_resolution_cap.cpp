// features/max_pixels: frames larger than the cap are shrunk before extraction, their keypoints
// mapped back to the frame's pixels, and verification widens its tolerances by the shrink
// (resolution_cap.hpp, Features::detection_scale).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/features/resolution_cap.hpp"
#include "mild_lcd/filter/filters.hpp"
#include "mild_lcd/place/keyframe_map.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"
#include "test_images.hpp"

namespace mild {
namespace {

cv::Mat resized(const cv::Mat& frame, cv::Size size) {
  cv::Mat out;
  cv::resize(frame, out, size, 0.0, 0.0, cv::INTER_CUBIC);
  return out;
}

cv::Mat enlarged(const cv::Mat& frame, double factor) {
  return resized(frame, cv::Size(static_cast<int>(frame.cols * factor), static_cast<int>(frame.rows * factor)));
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

// The capped extraction is the extractor's on the shrunk grey frame, each keypoint mapped back
// pixel centre to pixel centre per axis (752 x 480 under a 320 x 180 cap: 300 x 191, a shrink of
// 2.507 across and 2.513 down), its size by the mean factor, and the coarser factor recorded.
TEST(ResolutionCap, KeypointsAreTheShrunkFramesMappedBackPerAxis) {
  const cv::Mat frame = resized(test::sampleFrames().at(30), cv::Size(752, 480));
  const cv::Size small_size = ResolutionCap::shrunkSize(frame.size(), 320.0 * 180.0);
  ASSERT_EQ(small_size, cv::Size(300, 191));
  cv::Mat small;
  cv::resize(frame, small, small_size, 0.0, 0.0, cv::INTER_AREA);
  const Features direct = makeFeatureExtractor(capped("orb", 0.0))->extract(small, PixelFormat::kGray);
  const Features f = makeFeatureExtractor(capped("orb", 320.0 * 180.0))->extract(frame, PixelFormat::kGray);
  ASSERT_EQ(f.keypoints.size(), direct.keypoints.size());
  ASSERT_GT(f.keypoints.size(), 100u);
  const double sx = 752.0 / 300.0, sy = 480.0 / 191.0;
  for (size_t i = 0; i < f.keypoints.size(); ++i) {
    EXPECT_NEAR(f.keypoints[i].pt.x, (direct.keypoints[i].pt.x + 0.5) * sx - 0.5, 1e-3);
    EXPECT_NEAR(f.keypoints[i].pt.y, (direct.keypoints[i].pt.y + 0.5) * sy - 0.5, 1e-3);
    EXPECT_NEAR(f.keypoints[i].size, direct.keypoints[i].size * std::sqrt(sx * sy), 1e-3);
  }
  EXPECT_FLOAT_EQ(f.detection_scale, static_cast<float>(sy));
}

// A 1280 x 960 frame under a 320 x 240 cap costs what 320 x 240 costs: the budget of 320 x 240,
// keypoints spread over the whole frame in its own pixels, detection_scale 4; for every extractor.
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
    }
    EXPECT_GT(max_x, 1000.0f) << type << ": positions are the frame's pixels";
    EXPECT_LT(max_x, 1280.0f) << type;
    EXPECT_GT(max_y, 700.0f) << type;
    EXPECT_LT(max_y, 960.0f) << type;
  }
}

// Two views of one place, at 1280 x 960 under a 320 x 240 cap, verify as they do at 320 x 240: the
// 1-pixel tolerance is 4 of the frame's pixels for keypoints found at a quarter of its size, and the
// chance agreement is judged at that tolerance too (the significance stays within a few orders of
// magnitude). The coarser side decides: one side's scale alone widens as much. Without the widening
// the same keypoints keep fewer inliers.
TEST(ResolutionCap, VerificationWidensItsToleranceByTheCoarserSide) {
  const cv::Mat& a = test::sampleFrames().at(30);
  const cv::Mat& b = test::sampleFrames().at(33);
  const GeometricVerifier verifier{VerificationParams{}};
  const auto extractor_small = makeFeatureExtractor(capped("orb", 0.0));
  const Verification small =
      verifier.verify(extractor_small->extract(a, PixelFormat::kGray), extractor_small->extract(b, PixelFormat::kGray));
  const auto extractor_capped = makeFeatureExtractor(capped("orb", 320.0 * 240.0));
  Features qa = extractor_capped->extract(enlarged(a, 4.0), PixelFormat::kGray);
  Features qb = extractor_capped->extract(enlarged(b, 4.0), PixelFormat::kGray);
  const Verification widened = verifier.verify(qa, qb);
  ASSERT_GE(small.inliers, 40);
  EXPECT_GE(widened.inliers, small.inliers * 0.8) << "capped " << widened.inliers << ", 320 x 240 " << small.inliers;
  EXPECT_NEAR(widened.log10_false_alarms, small.log10_false_alarms, 0.25 * std::abs(small.log10_false_alarms))
      << "the significance is judged at the widened tolerance";
  qb.detection_scale = 1.0f;
  EXPECT_EQ(verifier.verify(qa, qb).inliers, widened.inliers) << "the coarser side's scale applies";
  qa.detection_scale = 1.0f;
  const Verification unwidened = verifier.verify(qa, qb);
  EXPECT_LT(unwidened.inliers, widened.inliers * 0.8) << "a quarter-size keypoint is not placed within 1 frame pixel";
  qa.detection_scale = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(verifier.verify(qa, qb).inliers, unwidened.inliers) << "a scale that is not a number is 1";
}

// A scale no shrink gives (1e30) widens as the widest allowed (64) and no further: it cannot make
// every match an inlier.
TEST(ResolutionCap, AnAbsurdScaleIsBounded) {
  const auto extractor = makeFeatureExtractor(capped("orb", 0.0));
  Features qa = extractor->extract(test::sampleFrames().at(30), PixelFormat::kGray);
  Features qb = extractor->extract(test::sampleFrames().at(33), PixelFormat::kGray);
  const GeometricVerifier verifier{VerificationParams{}};
  qa.detection_scale = kMaxDetectionScale;
  const Verification widest = verifier.verify(qa, qb);
  qa.detection_scale = 1e30f;
  const Verification absurd = verifier.verify(qa, qb);
  EXPECT_EQ(absurd.inliers, widest.inliers);
  EXPECT_EQ(absurd.log10_false_alarms, widest.log10_false_alarms);
}

// A stored keyframe keeps its scale, so that a later check against it (a SparseMatch of stored
// keyframes, a peer's pulled query) widens for it too.
TEST(ResolutionCap, AStoredKeyframeKeepsItsScale) {
  const Features f = makeFeatureExtractor(capped("orb", 320.0 * 240.0))
                         ->extract(enlarged(test::sampleFrames().at(30), 2.0), PixelFormat::kGray);
  ASSERT_FLOAT_EQ(f.detection_scale, 2.0f);
  KeyframeMap map(DatabaseParams{}, FilterParams{}, "orb");
  map.add(7, 0.0, f.keypoints, f.descriptors, f.camera, f.detection_scale);
  EXPECT_FLOAT_EQ(map.features(0).detection_scale, 2.0f);
}

// A frame a pixel thin shrinks to at most the cap, and to nothing a detector can use: no features,
// no failure.
TEST(ResolutionCap, AThinFrameStaysWithinTheCapAndYieldsNoFeatures) {
  EXPECT_EQ(ResolutionCap::shrunkSize(cv::Size(200000, 1), 4096.0), cv::Size(4096, 1));
  EXPECT_EQ(ResolutionCap::shrunkSize(cv::Size(1, 200000), 4096.0), cv::Size(1, 4096));
  const cv::Mat thin(1, 200000, CV_8UC1, cv::Scalar(128));
  for (const char* type : {"orb", "brisk", "akaze"}) {
    Features f;
    EXPECT_NO_THROW(f = makeFeatureExtractor(capped(type, 4096.0))->extract(thin, PixelFormat::kGray)) << type;
    EXPECT_TRUE(f.keypoints.empty()) << type;
  }
}

// A frame of another depth is refused as it is without the cap, before any resizing.
TEST(ResolutionCap, AFrameOfAnotherDepthIsRefusedAsInvalidInput) {
  const cv::Mat deep(480, 640, CV_16UC1, cv::Scalar(1000));
  EXPECT_THROW(makeFeatureExtractor(capped("orb", 320.0 * 240.0))->extract(deep, PixelFormat::kGray), InvalidInput);
}

TEST(ResolutionCap, ACapBelow64By64IsRefused) {
  EXPECT_THROW(makeFeatureExtractor(capped("orb", 1000.0)), InvalidInput);
  EXPECT_THROW(makeFeatureExtractor(capped("orb", -1.0)), InvalidInput);
  EXPECT_NO_THROW(makeFeatureExtractor(capped("orb", 4096.0)));
}

}  // namespace
}  // namespace mild
