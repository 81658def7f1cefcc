// rostest cases (nodelet_hostile.test) for input size bounds, against standalone nodes started here
// so that their memory can be read: messages over their bounds are rejected, counted and released,
// and no decoder allocates for a format whose header the node cannot judge. Part of test_nodelet
// (main() is there).

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>

#include <cv_bridge/cv_bridge.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <ros/ros.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/image_encodings.h>
#include <opencv2/imgcodecs.hpp>

#include "mild_lcd/Keyframe.h"
#include "mild_lcd/LoopClosure.h"
#include "ros_test_support.hpp"

namespace mild_lcd::test {
namespace {

// A standalone mild_lcd_node in `ns` with extra private parameters; stopped (SIGINT) when destroyed.
class StandaloneNode {
 public:
  StandaloneNode(const std::string& ns, const std::vector<std::string>& params)
      : ns_(ns), diagnostics_("/diagnostics") {
    pid_ = fork();
    if (pid_ == 0) {
      std::vector<std::string> args = {MILD_NODE_BIN, "__ns:=" + ns, "__name:=mild_lcd"};
      args.insert(args.end(), params.begin(), params.end());
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(MILD_NODE_BIN, argv.data());
      _exit(127);
    }
  }
  ~StandaloneNode() {
    if (pid_ <= 0) return;
    kill(pid_, SIGINT);
    int status = 0;
    waitpid(pid_, &status, 0);
  }

  // Peak resident memory of the node so far, in MB (VmHWM).
  double peakMb() const {
    std::ifstream status("/proc/" + std::to_string(pid_) + "/status");
    std::string line;
    while (std::getline(status, line)) {
      if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
    }
    return -1.0;
  }

  // Waits until the node's diagnostics report `key` = value; returns the last value seen.
  long waitForCount(const std::string& key, long value, double timeout_s) const {
    long seen = -1;
    const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout_s);
    while (ros::WallTime::now() < end) {
      for (const auto& array : diagnostics_.messages()) {
        for (const auto& status : array.status) {
          if (status.name.find(ns_.substr(1) + "/mild_lcd: ") == std::string::npos) continue;  // no leading /
          for (const auto& kv : status.values) {
            if (kv.key == key) seen = std::stol(kv.value);
          }
        }
      }
      if (seen == value) break;
      ros::WallDuration(0.1).sleep();
    }
    return seen;
  }

 private:
  std::string ns_;
  pid_t pid_ = -1;
  TopicLog<diagnostic_msgs::DiagnosticArray> diagnostics_;
};

sensor_msgs::ImagePtr noise(int width, int height, double stamp) {
  cv::Mat pixels(height, width, CV_8UC1);
  cv::randu(pixels, 0, 256);
  std_msgs::Header header;
  header.stamp = ros::Time(stamp);
  return cv_bridge::CvImage(header, sensor_msgs::image_encodings::MONO8, pixels).toImageMsg();
}

// Eight 320 x 240 images carrying 250 MB of data each (once: 79 MB -> 2.3 GB), a Keyframe of
// 20,000 keypoints and one with 8 MB of camera_info: each rejected and counted, none kept; the
// node's peak memory grows by about one message in flight, not by eight.
TEST(HostileInput, OversizeRawImagesAndKeyframesAreRejectedAndReleased) {
  StandaloneNode node("/bounds_raw", {});
  ros::NodeHandle nh;
  ros::Publisher images = nh.advertise<sensor_msgs::Image>("/bounds_raw/image", 1);
  ros::Publisher keyframes = nh.advertise<mild_lcd::Keyframe>("/bounds_raw/keyframe", 10);
  TopicLog<mild_lcd::LoopClosure> outputs("/bounds_raw/loop_closure");
  ASSERT_TRUE(outputs.waitForPublisher(30.0));
  ASSERT_TRUE(waitForSubscriber(images, 30.0));
  ASSERT_TRUE(waitForSubscriber(keyframes, 30.0));
  images.publish(noise(320, 240, 1.0));
  ASSERT_TRUE(outputs.waitForCount(1, 30.0));
  const double before = node.peakMb();

  sensor_msgs::Image huge = *noise(320, 240, 2.0);
  huge.data.resize(250u * 1000u * 1000u);  // the declared 320 x 240 and 250 MB more
  for (long i = 1; i <= 8; ++i) {
    images.publish(huge);
    ASSERT_EQ(node.waitForCount("rejected keyframes", i, 30.0), i) << "image " << i;
  }
  mild_lcd::Keyframe many;
  many.keypoints.resize(20000);
  many.descriptors.assign(20000 * 32, 7);
  keyframes.publish(many);
  mild_lcd::Keyframe extras;
  extras.keypoints.resize(10);
  extras.descriptors.assign(10 * 32, 7);
  extras.camera_info.D.assign(1000000, 0.0);
  keyframes.publish(extras);
  EXPECT_EQ(node.waitForCount("rejected keyframes", 10, 30.0), 10);
  images.publish(noise(320, 240, 3.0));
  ASSERT_TRUE(outputs.waitForCount(2, 30.0)) << "the node goes on";
  EXPECT_EQ(outputs.size(), 2u) << "nothing oversize was answered";
  const double growth = node.peakMb() - before;
  RecordProperty("peak_growth_mb", std::to_string(growth));
  std::cout << "peak resident memory grew by " << growth << " MB over " << before << " MB" << std::endl;
  EXPECT_LT(growth, 1000.0) << "eight 250 MB messages were held at once";
}

// A 20000 x 20000 TIFF of 600 KB: OpenCV's TIFF decoder allocates (and fills) 400 MB for it before
// anything could judge it. It is refused on its first bytes, never decoded.
TEST(HostileInput, ATiffIsRefusedWithoutDecodingIt) {
  std::vector<uint8_t> tiff;
  ASSERT_TRUE(cv::imencode(".tiff", cv::Mat(20000, 20000, CV_8UC1, cv::Scalar(0)), tiff));
  StandaloneNode node("/bounds_tiff", {"_image_transport:=compressed", "_use_keyframe_input:=false"});
  ros::NodeHandle nh;
  ros::Publisher images = nh.advertise<sensor_msgs::CompressedImage>("/bounds_tiff/image/compressed", 1);
  TopicLog<mild_lcd::LoopClosure> outputs("/bounds_tiff/loop_closure");
  ASSERT_TRUE(outputs.waitForPublisher(30.0));
  ASSERT_TRUE(waitForSubscriber(images, 30.0));
  const double before = node.peakMb();
  sensor_msgs::CompressedImage msg;
  msg.format = "tiff";
  msg.data = tiff;
  images.publish(msg);
  EXPECT_EQ(node.waitForCount("rejected keyframes", 1, 30.0), 1);
  const double growth = node.peakMb() - before;
  std::cout << tiff.size() / 1000 << " KB TIFF: peak resident memory grew by " << growth << " MB" << std::endl;
  EXPECT_LT(growth, 150.0) << "the TIFF was decoded";
  msg.format = "jpeg";
  ASSERT_TRUE(cv::imencode(".jpg", cv::Mat(240, 320, CV_8UC1, cv::Scalar(90)), msg.data));
  images.publish(msg);
  EXPECT_TRUE(outputs.waitForCount(1, 30.0)) << "a JPEG after it is answered";
}

}  // namespace
}  // namespace mild_lcd::test
