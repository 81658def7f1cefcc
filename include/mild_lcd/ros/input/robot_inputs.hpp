#pragma once

// One robot's inputs: `image` (image_transport, with camera_info beside it) and `keyframe`, in the
// robot's namespace (the node's own for a node serving one robot). Their callbacks run on a
// callback queue and thread of their own, not on the nodelet's queue, which also serves live tuning
// and diagnostics: nothing else can hold them up, so roscpp's subscriber queue is emptied as fast as
// messages arrive, and only the worker's queue, which counts what it drops, can overflow. Callbacks
// only queue the keyframe, tagged with the robot, for the worker; they never wait for the detector.

#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include <image_transport/image_transport.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include "mild_lcd/ros/detection/keyframe_worker.hpp"
#include "mild_lcd/ros/settings/node_settings.hpp"

namespace mild_lcd {

class RobotInputs {
 public:
  using Enqueue = std::function<void(KeyframeInputPtr)>;
  // Subscribes as the settings say. `log_name` names the nodelet in messages.
  RobotInputs(ros::NodeHandle& nh, ros::NodeHandle& pnh, size_t robot, const NodeSettings& settings,
              const std::string& log_name, Enqueue enqueue);
  ~RobotInputs() { shutdown(); }
  void shutdown();

  // Throws mild::InvalidInput when ~image_transport names no installed plugin (checked before any
  // subscription exists; compressed is decoded by mild_lcd when its plugin is missing).
  static void checkTransport(ros::NodeHandle& nh, const NodeSettings& settings);

 private:
  static bool decodesCompressedItself(ros::NodeHandle& nh, const NodeSettings& settings);
  void subscribeImages(ros::NodeHandle& nh, ros::NodeHandle& pnh);
  void subscribeCameraInfo(ros::NodeHandle& nh);
  mild::CameraIntrinsics latestCamera();

  size_t robot_;
  const NodeSettings& settings_;
  std::string log_name_;
  Enqueue enqueue_;
  ros::CallbackQueue queue_;  // the inputs' own; declared before what uses it, so destroyed after
  ros::NodeHandle nh_;        // the robot's namespace, on queue_
  std::unique_ptr<ros::AsyncSpinner> spinner_;
  // Declared before the subscribers that use its plugins, so destroyed after them.
  std::unique_ptr<image_transport::ImageTransport> transport_;
  image_transport::Subscriber image_sub_;
  ros::Subscriber compressed_sub_, keyframe_sub_, camera_info_sub_;
  std::mutex camera_mutex_;
  mild::CameraIntrinsics camera_;  // newest from camera_info
};

}  // namespace mild_lcd
