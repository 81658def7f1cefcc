#pragma once

// The ROS layer's input adapters: one per input kind (image, compressed image, Keyframe message),
// each turning its message into the pipeline's one mild::Observation (robot_localization's
// Measurement is the model). The worker and its queue see only KeyframeInput; a new input kind is
// a new adapter here and its subscription (robot_inputs.cpp), nothing in the worker.

#include <cstddef>
#include <memory>

#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/Header.h>

#include "mild_lcd/Keyframe.h"
#include "mild_lcd/detector/observation.hpp"
#include "mild_lcd/ros/input/image_decoding.hpp"
#include "mild_lcd/ros/input/input_admission.hpp"

namespace mild_lcd {

// One keyframe message as it arrived, for robot `robot()` (the index in the team; 0 for one robot).
// It holds the message until it is observed; nothing is decoded before.
class KeyframeInput {
 public:
  explicit KeyframeInput(size_t robot) : robot_(robot) {}
  virtual ~KeyframeInput() = default;

  size_t robot() const { return robot_; }
  virtual const std_msgs::Header& header() const = 0;
  // The message's size in bytes, for the queue's bound; throws InvalidInput when the message is over
  // `limits` (checkedInputBytes), judged without decoding anything.
  virtual size_t checkedBytes(const InputLimits& limits) const = 0;
  // Decodes the message into the observation the pipeline takes. An image input also leaves its
  // decoded image in `decoded` (for the debug image); others leave it empty. Throws InvalidInput for
  // an unusable message.
  virtual mild::Observation observe(const InputLimits& limits, DecodedImage& decoded) const = 0;

 private:
  size_t robot_;
};
using KeyframeInputPtr = std::unique_ptr<KeyframeInput>;

// The adapters. `camera`: the image's intrinsics (from camera_info) when known; a Keyframe message
// carries its own.
KeyframeInputPtr imageInput(sensor_msgs::ImageConstPtr msg, const mild::CameraIntrinsics& camera = {},
                            size_t robot = 0);
KeyframeInputPtr compressedImageInput(sensor_msgs::CompressedImageConstPtr msg,
                                      const mild::CameraIntrinsics& camera = {}, size_t robot = 0);
KeyframeInputPtr keyframeInput(mild_lcd::KeyframeConstPtr msg, size_t robot = 0);

}  // namespace mild_lcd
