#pragma once

// What the tests of the ROS layer's parts (test/ros/parts/, binary test_ros_parts) share: settings
// from YAML, images and keyframe messages, polling, a worker's recorded answers. No master needed.

#include <gtest/gtest.h>

#include <unistd.h>

#include <sensor_msgs/image_encodings.h>
#include <atomic>
#include <boost/make_shared.hpp>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "../../common/scratch_folder.hpp"
#include "../../core/error_text.hpp"
#include "../../core/fixture_params.hpp"
#include "../../core/test_images.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "mild_lcd/ros/detection/database_store.hpp"
#include "mild_lcd/ros/detection/keyframe_worker.hpp"
#include "mild_lcd/ros/detection/periodic_task.hpp"
#include "mild_lcd/ros/input/image_decoding.hpp"
#include "mild_lcd/ros/input/input_admission.hpp"
#include "mild_lcd/ros/messages/message_conversions.hpp"
#include "mild_lcd/ros/output/debug_image.hpp"
#include "mild_lcd/ros/services/sparse_match_service.hpp"
#include "mild_lcd/ros/settings/node_settings.hpp"
#include "mild_lcd/ros/settings/tuning_config.hpp"

namespace mild_lcd::ros_parts_test {

namespace fs = std::filesystem;

using mild::YamlParameterSource;
using mild::test::errorOf;
using mild::test::fixtureParams;

inline NodeSettings settingsFrom(const std::string& yaml, const std::string& default_dir = "/tmp/mild_default") {
  return NodeSettings::load(YamlParameterSource::fromString(yaml), default_dir);
}

// Polls `done` until it holds; false after `timeout`, so that a broken worker fails a test rather
// than hanging it.
inline bool eventually(const std::function<bool()>& done,
                       std::chrono::milliseconds timeout = std::chrono::seconds(20)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

inline sensor_msgs::ImagePtr image(int width, int height, double stamp, const std::string& encoding = "mono8") {
  auto msg = boost::make_shared<sensor_msgs::Image>();
  msg->header.stamp = ros::Time(stamp);
  msg->width = static_cast<uint32_t>(width);
  msg->height = static_cast<uint32_t>(height);
  msg->encoding = encoding;
  msg->step = static_cast<uint32_t>(width);
  msg->data.resize(static_cast<size_t>(width) * static_cast<size_t>(height));
  cv::RNG rng(static_cast<uint64_t>(stamp * 10) + 1);
  for (auto& b : msg->data) b = static_cast<uint8_t>(rng.uniform(0, 256));
  return msg;
}

// --- the worker's two stages (~extraction_thread): keyframe k+1 decoded and extracted while k is
// queried, verified and stored.

inline sensor_msgs::ImagePtr imageOf(const cv::Mat& grey, double stamp) {
  auto msg = boost::make_shared<sensor_msgs::Image>();
  msg->header.stamp = ros::Time(stamp);
  msg->width = static_cast<uint32_t>(grey.cols);
  msg->height = static_cast<uint32_t>(grey.rows);
  msg->encoding = sensor_msgs::image_encodings::MONO8;
  msg->step = static_cast<uint32_t>(grey.cols);
  msg->data.assign(grey.data, grey.data + grey.total());
  return msg;
}

// Everything a keyframe's answer says, in the order the answers came.
struct Answers {
  std::mutex mutex;
  std::vector<ProcessedKeyframe> published;
  std::vector<std::string> events;  // "answered (stamp s)" or the warning of a refusal, in order
};

inline KeyframeWorker::Hooks recordingHooks(Answers& answers) {
  KeyframeWorker::Hooks hooks;
  hooks.publish = [&answers](const ProcessedKeyframe& k) {
    std::lock_guard<std::mutex> lock(answers.mutex);
    answers.published.push_back(k);
    answers.events.push_back("answered (stamp " + std::to_string(k.header.stamp.toSec()) + ")");
  };
  hooks.warn = [&answers](const std::string& what) {
    std::lock_guard<std::mutex> lock(answers.mutex);
    answers.events.push_back(what);
  };
  return hooks;
}

inline mild_lcd::KeyframePtr keyframeMsg(double stamp, std::optional<uint64_t> id, uint32_t descriptor_bytes = 32) {
  auto kf = boost::make_shared<mild_lcd::Keyframe>();
  kf->header.stamp = ros::Time(stamp);
  kf->has_id = id.has_value();
  kf->id = id.value_or(0);
  kf->descriptor_bytes = descriptor_bytes;
  kf->keypoints.resize(3);
  for (size_t i = 0; i < 3; ++i) kf->keypoints[i].x = kf->keypoints[i].y = 10.0f * static_cast<float>(i + 1);
  kf->descriptors.assign(3 * descriptor_bytes, static_cast<uint8_t>(stamp));
  return kf;
}

// A PNG whose header passes the size checks made as it is pushed, and whose pixels do not decode.
inline sensor_msgs::CompressedImagePtr corruptPng(double stamp) {
  auto msg = boost::make_shared<sensor_msgs::CompressedImage>();
  msg->header.stamp = ros::Time(stamp);
  msg->format = "png";
  cv::imencode(".png", cv::Mat(40, 40, CV_8UC1, cv::Scalar(90)), msg->data);
  for (size_t i = 41; i + 12 < msg->data.size(); ++i) msg->data[i] ^= 0x5A;  // IDAT's data, not IHDR
  return msg;
}

}  // namespace mild_lcd::ros_parts_test
