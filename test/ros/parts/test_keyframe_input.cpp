// test_ros_parts: the keyframe inputs (ros/keyframe_input.hpp): each kind becomes one observation.

#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

// Each input kind has its adapter, and each yields the one observation the pipeline takes.
TEST(KeyframeInputs, EachKindBecomesOneObservation) {
  const mild::CameraIntrinsics camera{300.0, 300.0, 100.0, 75.0};
  DecodedImage decoded;
  const KeyframeInputPtr raw = imageInput(image(200, 150, 1.5), camera, 2);
  EXPECT_EQ(raw->robot(), 2u);
  EXPECT_DOUBLE_EQ(raw->header().stamp.toSec(), 1.5);
  EXPECT_GE(raw->checkedBytes(InputLimits{}), 200u * 150u) << "the pixels and the header";
  const mild::Observation from_image = raw->observe(InputLimits{}, decoded);
  ASSERT_TRUE(from_image.image.has_value());
  EXPECT_EQ(from_image.image->pixels.size(), cv::Size(200, 150));
  EXPECT_EQ(decoded.image.size(), cv::Size(200, 150)) << "kept for the debug image";
  EXPECT_EQ(from_image.features.camera, camera);
  EXPECT_DOUBLE_EQ(from_image.stamp, 1.5);
  EXPECT_FALSE(from_image.id.has_value());
  EXPECT_EQ(from_image.robot, 2u);

  auto compressed = boost::make_shared<sensor_msgs::CompressedImage>();
  compressed->header.stamp = ros::Time(2.0);
  compressed->format = "png";
  cv::imencode(".png", cv::Mat(120, 160, CV_8UC1, cv::Scalar(7)), compressed->data);
  const mild::Observation from_png = compressedImageInput(compressed, {}, 1)->observe(InputLimits{}, decoded);
  ASSERT_TRUE(from_png.image.has_value());
  EXPECT_EQ(from_png.image->pixels.size(), cv::Size(160, 120));
  EXPECT_EQ(from_png.robot, 1u);

  auto keyframe = boost::make_shared<mild_lcd::Keyframe>();
  keyframe->header.stamp = ros::Time(3.0);
  keyframe->has_id = true;
  keyframe->id = 42;
  const mild::Observation from_features = keyframeInput(keyframe)->observe(InputLimits{}, decoded);
  EXPECT_FALSE(from_features.image.has_value());
  EXPECT_TRUE(decoded.image.empty()) << "no image to draw on";
  EXPECT_EQ(from_features.id, std::optional<uint64_t>(42));
  EXPECT_DOUBLE_EQ(from_features.stamp, 3.0);
  EXPECT_TRUE(from_features.features.keypoints.empty());
}

}  // namespace
}  // namespace mild_lcd
