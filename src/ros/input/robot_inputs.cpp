#include "mild_lcd/ros/input/robot_inputs.hpp"

#include <algorithm>

#include <image_transport/camera_common.h>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/ros/messages/message_conversions.hpp"

namespace mild_lcd {

RobotInputs::RobotInputs(ros::NodeHandle& nh, ros::NodeHandle& pnh, size_t robot, const NodeSettings& settings,
                         const std::string& log_name, Enqueue enqueue)
    : robot_(robot), settings_(settings), log_name_(log_name), enqueue_(std::move(enqueue)), nh_(nh) {
  nh_.setCallbackQueue(&queue_);
  transport_ = std::make_unique<image_transport::ImageTransport>(nh_);
  if (settings_.use_image_input && settings_.use_camera_info) subscribeCameraInfo(nh_);
  if (settings_.use_image_input) subscribeImages(nh_, pnh);
  if (settings_.use_keyframe_input) {
    keyframe_sub_ = nh_.subscribe<mild_lcd::Keyframe>(
        "keyframe", settings_.queue_size,
        [this](const mild_lcd::KeyframeConstPtr& m) { enqueue_(keyframeInput(m, robot_)); });
    ROS_INFO_STREAM_NAMED(log_name_, "subscribed to " << keyframe_sub_.getTopic() << " (keyframe features)");
  }
  spinner_ = std::make_unique<ros::AsyncSpinner>(1, &queue_);
  spinner_->start();
}

void RobotInputs::shutdown() {
  image_sub_.shutdown();
  camera_info_sub_.shutdown();
  compressed_sub_.shutdown();
  keyframe_sub_.shutdown();
  if (spinner_) spinner_->stop();  // waits for a callback in progress
  spinner_.reset();
}

// image_transport's `compressed` plugin is not packaged for Debian's ROS; without it the compressed
// topic is subscribed and decoded here, so `~image_transport: compressed` works either way. Any
// other name must be an installed plugin.
bool RobotInputs::decodesCompressedItself(ros::NodeHandle& nh, const NodeSettings& settings) {
  if (settings.image_transport != "compressed") return false;
  const auto loadable = image_transport::ImageTransport(nh).getLoadableTransports();
  return std::find(loadable.begin(), loadable.end(), "image_transport/compressed") == loadable.end();
}

void RobotInputs::checkTransport(ros::NodeHandle& nh, const NodeSettings& settings) {
  if (decodesCompressedItself(nh, settings)) return;
  const auto loadable = image_transport::ImageTransport(nh).getLoadableTransports();
  if (std::find(loadable.begin(), loadable.end(), "image_transport/" + settings.image_transport) != loadable.end())
    return;
  std::string names;
  for (const auto& t : loadable) names += (names.empty() ? "" : ", ") + t.substr(t.find('/') + 1);
  throw mild::InvalidInput("parameter ~image_transport: no transport plugin '" + settings.image_transport +
                           "' is installed (installed: " + names + (names.empty() ? "" : ", ") +
                           "and compressed, which mild_lcd decodes itself)");
}

void RobotInputs::subscribeImages(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
  if (decodesCompressedItself(nh, settings_)) {
    const std::string topic = nh.resolveName("image") + "/compressed";
    compressed_sub_ = nh.subscribe<sensor_msgs::CompressedImage>(
        topic, settings_.queue_size, [this](const sensor_msgs::CompressedImageConstPtr& m) {
          enqueue_(compressedImageInput(m, latestCamera(), robot_));
        });
    ROS_INFO_STREAM_NAMED(log_name_, "subscribed to " << topic << " (compressed images, decoded by mild_lcd)");
    return;
  }
  image_sub_ = transport_->subscribe(
      "image", settings_.queue_size,
      [this](const sensor_msgs::ImageConstPtr& m) { enqueue_(imageInput(m, latestCamera(), robot_)); }, ros::VoidPtr(),
      image_transport::TransportHints(settings_.image_transport, ros::TransportHints(), pnh));
  ROS_INFO_STREAM_NAMED(
      log_name_, "subscribed to " << image_sub_.getTopic() << " (transport " << settings_.image_transport << ")");
}

// camera_info beside `image` (image_transport's naming). Not a synchronised camera subscriber: an
// image whose camera_info never comes (many bags and drivers lack one) must still be processed, and
// intrinsics rarely change, so each image takes the newest intrinsics received before it.
void RobotInputs::subscribeCameraInfo(ros::NodeHandle& nh) {
  const std::string topic = image_transport::getCameraInfoTopic(nh.resolveName("image"));
  camera_info_sub_ = nh.subscribe<sensor_msgs::CameraInfo>(topic, 1, [this](const sensor_msgs::CameraInfoConstPtr& m) {
    try {
      const mild::CameraIntrinsics camera = intrinsicsFromMsg(*m);
      std::lock_guard<std::mutex> lock(camera_mutex_);
      if (camera != camera_ && camera.known()) {
        ROS_INFO_NAMED(log_name_, "camera intrinsics from %s: fx %.2f fy %.2f cx %.2f cy %.2f",
                       camera_info_sub_.getTopic().c_str(), camera.fx, camera.fy, camera.cx, camera.cy);
      }
      camera_ = camera;
    } catch (const mild::InvalidInput& e) {
      ROS_WARN_STREAM_THROTTLE_NAMED(10.0, log_name_, "ignored camera_info: " << e.what());
    }
  });
  ROS_INFO_STREAM_NAMED(log_name_, "subscribed to " << topic << " (intrinsics for verified loops' relative pose)");
}

mild::CameraIntrinsics RobotInputs::latestCamera() {
  std::lock_guard<std::mutex> lock(camera_mutex_);
  return camera_;
}

}  // namespace mild_lcd
