// How many features an image keeps: num_features is meant for features/reference_pixels pixels
// (320 x 240) and scales with the square root of the image's area (featureBudget).
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "mild_lcd/features/feature_source.hpp"
#include "test_images.hpp"

namespace mild {
namespace {

TEST(FeatureBudget, ScalesWithTheSquareRootOfTheAreaWithinFourTimes) {
  constexpr double kReference = 320.0 * 240.0;
  EXPECT_EQ(featureBudget(800, 320 * 240, kReference), 800u);
  EXPECT_EQ(featureBudget(800, 640 * 480, kReference), 1600u);  // four times the area, twice the features
  EXPECT_EQ(featureBudget(800, 640 * 360, kReference), 1386u);
  EXPECT_EQ(featureBudget(800, 160 * 120, kReference), 400u);
  EXPECT_EQ(featureBudget(800, 7680 * 4320, kReference), 3200u) << "at most four times num_features";
  EXPECT_EQ(featureBudget(800, 1, kReference), 3u);
  EXPECT_EQ(featureBudget(800, 0, kReference), 1u) << "never 0: an empty budget would mean no limit to OpenCV";
  EXPECT_EQ(featureBudget(800, 7680 * 4320, 0.0), 800u) << "reference_pixels 0: num_features at any size";
}

// The same scene at twice the resolution keeps about twice the features, through the factory the
// detector uses; with reference_pixels 0 it keeps num_features.
TEST(FeatureBudget, ALargerImageOfTheSameSceneKeepsMoreFeatures) {
  const cv::Mat frame = test::sampleFrames().at(30);  // 320 x 240
  ASSERT_EQ(frame.total(), 320u * 240u);
  cv::Mat large;
  cv::resize(frame, large, cv::Size(), 2.0, 2.0, cv::INTER_CUBIC);
  for (const char* type : {"orb", "brisk", "akaze"}) {
    FeatureParams params;
    params.type = type;
    forEachSection(params.extractors, [](auto& section) { section.num_features = 100; });
    const size_t small_count = makeFeatureExtractor(params)->extract(frame, PixelFormat::kGray).keypoints.size();
    const size_t large_count = makeFeatureExtractor(params)->extract(large, PixelFormat::kGray).keypoints.size();
    // At most the budget (OpenCV's ORB may return a few fewer: it fills its pyramid level by level).
    EXPECT_LE(small_count, 100u) << type;
    EXPECT_GE(small_count, 90u) << type;
    EXPECT_LE(large_count, 200u) << type;
    EXPECT_GE(large_count, 180u) << type;
    params.reference_pixels = 0.0;
    EXPECT_LE(makeFeatureExtractor(params)->extract(large, PixelFormat::kGray).keypoints.size(), 100u) << type;
  }
}

}  // namespace
}  // namespace mild
