// test_ros_parts: the debug image cache and drawing (ros/debug_image.hpp).

#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

TEST(DebugImages, TheCacheIsBoundedInBytes) {
  DebugImageCache cache(1000, 4u << 20);
  for (uint64_t id = 0; id < 20; ++id)
    cache.remember(id, cv::Mat(2000, 2000, CV_8UC1, cv::Scalar(1)), mild::PixelFormat::kGray);
  EXPECT_LE(cache.bytes(), 4u << 20);
  EXPECT_FALSE(cache.find(19).empty()) << "the newest stays";
  EXPECT_TRUE(cache.find(0).empty());
  cache.remember(50, cv::Mat(1, 1, CV_8UC1, cv::Scalar(9)), mild::PixelFormat::kGray);  // no half of one pixel
  EXPECT_FALSE(cache.find(50).empty());
}

TEST(DebugImages, KeepTheDecodedChannelOrder) {
  cv::Mat rgb(40, 40, CV_8UC3, cv::Scalar(255, 0, 0));  // pure red as RGB
  DebugImageCache cache(10, 1u << 20);
  cache.remember(1, rgb, mild::PixelFormat::kRgb);
  cache.remember(2, rgb, mild::PixelFormat::kBgr);  // the same bytes read as BGR: blue
  EXPECT_NE(cache.find(1).at<uint8_t>(5, 5), cache.find(2).at<uint8_t>(5, 5));
  EXPECT_EQ(cache.find(1).at<uint8_t>(5, 5), 76) << "red's luma (0.299 x 255)";
}

// The picture shows what it says: query left and candidate right at half resolution, the inlier
// drawn as a green line from the query's keypoint to the candidate's, unmatched keypoints as grey
// circles, and a label; without a candidate, the query alone labelled in red.
TEST(DebugImages, DrawTheInliersWhereTheKeypointsAre) {
  const cv::Mat query(200, 320, CV_8UC1, cv::Scalar(0));
  const cv::Mat candidate(100, 160, CV_8UC1, cv::Scalar(0));  // cached at half resolution, as the cache keeps it
  const cv::Mat query_half(100, 160, CV_8UC1, cv::Scalar(0));
  const std::vector<cv::KeyPoint> query_kps = {cv::KeyPoint(80, 120, 8), cv::KeyPoint(240, 40, 8)};
  const std::vector<cv::KeyPoint> candidate_kps = {cv::KeyPoint(200, 160, 8)};
  mild::DetectionResult result;
  result.query_id = 7;
  mild::LoopCandidate best;
  best.id = 3;
  best.verification.verified = true;
  best.verification.inliers = 1;
  best.verification.inlier_matches = {mild::FeatureMatch{0, 0, 10}};
  result.candidates.push_back(best);
  const cv::Mat canvas = drawDebugImage(query_half, query_kps, candidate, candidate_kps, result);
  ASSERT_EQ(canvas.type(), CV_8UC3);
  ASSERT_EQ(canvas.size(), cv::Size(320, 100));
  const auto green = [&](cv::Point p) {
    const cv::Vec3b c = canvas.at<cv::Vec3b>(p);
    return c[1] > 100 && c[0] < c[1] / 2 && c[2] < c[1] / 2;
  };
  // Query keypoint 0 is at (40, 60) in the half image, candidate keypoint 0 at (100, 80) + 160.
  const cv::Point from(40, 60), to(160 + 100, 80);
  const cv::Point middle((from.x + to.x) / 2, (from.y + to.y) / 2);
  int on_line = 0;
  for (int dy = -1; dy <= 1; ++dy) on_line += green(middle + cv::Point(0, dy)) ? 1 : 0;
  EXPECT_GT(on_line, 0) << "the inlier's line passes between the two keypoints";
  EXPECT_FALSE(green(cv::Point(40, 90))) << "nothing green away from the match";
  // The unmatched query keypoint (120, 20) is drawn as a grey circle of its (halved) size.
  bool grey = false;
  for (int y = 14; y <= 26 && !grey; ++y) {
    for (int x = 114; x <= 126 && !grey; ++x) {
      const cv::Vec3b c = canvas.at<cv::Vec3b>(y, x);
      grey = c[0] > 40 && c[0] == c[1] && c[1] == c[2];
    }
  }
  EXPECT_TRUE(grey) << "the unmatched keypoint is drawn where it is";
  EXPECT_EQ(canvas.at<cv::Vec3b>(95, 80), cv::Vec3b(0, 0, 0)) << "the images themselves are untouched elsewhere";
  // The label (green: verified) is written in the top-left corner.
  int label = 0;
  for (int y = 2; y < 18; ++y) {
    for (int x = 5; x < 150; ++x) label += green(cv::Point(x, y)) ? 1 : 0;
  }
  EXPECT_GT(label, 20) << "a green label for a verified loop";

  mild::DetectionResult none;
  const cv::Mat alone = drawDebugImage(query_half, query_kps, cv::Mat(), {}, none);
  ASSERT_EQ(alone.size(), cv::Size(160, 100)) << "the query alone";
  int red = 0;
  for (int y = 2; y < 18; ++y) {
    for (int x = 5; x < 150; ++x) {
      const cv::Vec3b c = alone.at<cv::Vec3b>(y, x);
      red += c[2] > 200 && c[0] < 50 && c[1] < 50 ? 1 : 0;
    }
  }
  EXPECT_GT(red, 20) << "\"no candidate\" in red";
}

}  // namespace
}  // namespace mild_lcd
