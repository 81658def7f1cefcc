#include "mild_lcd/ros/input/keyframe_input.hpp"

#include "mild_lcd/ros/messages/message_conversions.hpp"

#include <optional>
#include <utility>

namespace mild_lcd {
namespace {

// sensor_msgs/Image and sensor_msgs/CompressedImage: decoded here, features extracted by the
// worker's front-end (mild::FeatureFrontEnd, features/type).
template <class Msg>
class ImageMessageInput : public KeyframeInput {
 public:
  ImageMessageInput(boost::shared_ptr<const Msg> msg, const mild::CameraIntrinsics& camera, size_t robot)
      : KeyframeInput(robot), msg_(std::move(msg)), camera_(camera) {}
  const std_msgs::Header& header() const override { return msg_->header; }
  size_t checkedBytes(const InputLimits& limits) const override { return checkedInputBytes(*msg_, limits); }
  mild::Observation observe(const InputLimits& limits, DecodedImage& decoded) const override {
    decoded = imageFromMsg(*msg_, limits.max_image_pixels);
    return mild::Observation::ofImage(decoded.image, decoded.format, msg_->header.stamp.toSec(), std::nullopt, camera_,
                                      robot());
  }

 private:
  boost::shared_ptr<const Msg> msg_;
  mild::CameraIntrinsics camera_;
};

// mild_lcd/Keyframe: a front-end's features, with its own camera, depths and id.
class KeyframeMessageInput : public KeyframeInput {
 public:
  KeyframeMessageInput(mild_lcd::KeyframeConstPtr msg, size_t robot) : KeyframeInput(robot), msg_(std::move(msg)) {}
  const std_msgs::Header& header() const override { return msg_->header; }
  size_t checkedBytes(const InputLimits& limits) const override { return checkedInputBytes(*msg_, limits); }
  mild::Observation observe(const InputLimits&, DecodedImage& decoded) const override {
    decoded = DecodedImage{};
    const std::optional<uint64_t> id = msg_->has_id ? std::optional<uint64_t>(msg_->id) : std::nullopt;
    return mild::Observation::ofFeatures(featuresFromMsg(*msg_), msg_->header.stamp.toSec(), id, robot());
  }

 private:
  mild_lcd::KeyframeConstPtr msg_;
};

}  // namespace

KeyframeInputPtr imageInput(sensor_msgs::ImageConstPtr msg, const mild::CameraIntrinsics& camera, size_t robot) {
  return std::make_unique<ImageMessageInput<sensor_msgs::Image>>(std::move(msg), camera, robot);
}

KeyframeInputPtr compressedImageInput(sensor_msgs::CompressedImageConstPtr msg, const mild::CameraIntrinsics& camera,
                                      size_t robot) {
  return std::make_unique<ImageMessageInput<sensor_msgs::CompressedImage>>(std::move(msg), camera, robot);
}

KeyframeInputPtr keyframeInput(mild_lcd::KeyframeConstPtr msg, size_t robot) {
  return std::make_unique<KeyframeMessageInput>(std::move(msg), robot);
}

}  // namespace mild_lcd
