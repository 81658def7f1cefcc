// rostest cases for a detector that is busy for seconds (nodelet_busy.test): nothing on the input
// path may wait for it. Part of test_nodelet (main() is there).

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <thread>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <ros/ros.h>

#include "mild_lcd/Keyframe.h"
#include "mild_lcd/LoadDatabase.h"
#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "ros_test_support.hpp"

namespace fs = std::filesystem;

namespace mild_lcd::test {
namespace {

// The nodelet's ~database_dir (nodelet_busy.test sets the same folder).
fs::path busyDir() {
  const char* home = std::getenv("ROS_HOME");
  const fs::path d = fs::path(home && *home ? home : "/tmp") / "mild_busy_test";
  fs::create_directories(d);
  return d;
}

mild::Descriptor randomDescriptor(cv::RNG& rng) {
  mild::Descriptor d;  // ORB's 32 bytes
  for (int w = 0; w < d.numWords(); ++w) d.words[w] = (static_cast<uint64_t>(rng.next()) << 32) | rng.next();
  return d;
}

// A map of `keyframes` x `features` random features under ids from 1,000,000: merging it rebuilds
// an index of that many features while the merge holds the detector.
void writeLargeMap(const std::string& path, size_t keyframes, size_t features) {
  mild::MapState state;
  state.parameters = "";
  cv::RNG rng(17);
  for (size_t k = 0; k < keyframes; ++k) {
    mild::KeyframeRecord record;
    record.id = 1000000 + k;
    record.stamp = 1.0 + 0.1 * static_cast<double>(k);
    mild::DescriptorList descriptors;
    for (size_t i = 0; i < features; ++i) {
      record.keypoints.emplace_back(static_cast<float>(i % 320), static_cast<float>(i / 320), 7.0f);
      descriptors.push_back(randomDescriptor(rng));
    }
    state.records.push_back(std::move(record));
    state.descriptors.push_back(std::move(descriptors));
  }
  state.next_id = 1000000 + keyframes;
  mild::LoopDetector detector;
  detector.map().restore(std::move(state), false);
  mild::saveMap(detector.map(), path);
}

mild_lcd::Keyframe randomKeyframe(cv::RNG& rng, double stamp) {
  mild_lcd::Keyframe kf;
  kf.header.stamp = ros::Time(stamp);
  for (int i = 0; i < 200; ++i) {
    mild_lcd::KeyPoint p;
    p.x = static_cast<float>(rng.uniform(0, 320));
    p.y = static_cast<float>(rng.uniform(0, 240));
    p.size = 7.0f;
    kf.keypoints.push_back(p);
    for (int b = 0; b < 32; ++b) kf.descriptors.push_back(static_cast<uint8_t>(rng.uniform(0, 256)));
  }
  return kf;
}

// The latest of mild_lcd's diagnostic values, as numbers.
class DetectorCounters {
 public:
  DetectorCounters() : log_("/diagnostics") {}
  // The latest value of `key` (-1 before any report).
  long counted(const std::string& key) const {
    long value = -1;
    for (const auto& array : log_.messages()) {
      for (const auto& status : array.status) {
        if (status.name.find("loop closure detector") == std::string::npos) continue;
        for (const auto& kv : status.values) {
          if (kv.key == key) value = std::stol(kv.value);
        }
      }
    }
    return value;
  }

 private:
  TopicLog<diagnostic_msgs::DiagnosticArray> log_;
};

// One dynamic_reconfigure request while a merge of a large map holds the detector and keyframes
// arrive at 50 Hz: the request is applied, and every keyframe sent is answered, or counted as
// dropped (the worker's queue overflowed while the detector was held), rejected or discarded. The
// dynamic_reconfigure server runs on the nodelet's callback queue; when its callback waited for
// the detector, the keyframe callbacks behind it could not run, roscpp's own queue overflowed and
// the keyframes it discarded were neither answered nor counted.
TEST(BusyDetector, ARetuneDuringALongMergeLosesNoKeyframe) {
  const std::string map = (busyDir() / "large.mild").string();
  writeLargeMap(map, 3000, 300);

  ros::NodeHandle nh;
  ros::Publisher keyframes = nh.advertise<mild_lcd::Keyframe>("/camera/keyframe", 1000);
  TopicLog<mild_lcd::LoopClosure> outputs("/loop_closure", 1000);
  DetectorCounters counters;
  ASSERT_TRUE(outputs.waitForPublisher(30.0));
  ASSERT_TRUE(waitForSubscriber(keyframes, 30.0));
  ASSERT_TRUE(ros::service::waitForService("/load_database", ros::Duration(20.0)));
  ASSERT_TRUE(ros::service::waitForService("/mild_lcd/tuning/set_parameters", ros::Duration(20.0)));

  constexpr int kSent = 400;  // 8 s at 50 Hz
  std::atomic<int> sent{0};
  std::thread stream([&] {
    cv::RNG rng(23);
    for (int i = 0; i < kSent; ++i) {
      keyframes.publish(randomKeyframe(rng, 100.0 + 0.02 * i));
      ++sent;
      ros::WallDuration(0.02).sleep();
    }
  });
  while (sent < 50) ros::WallDuration(0.01).sleep();
  mild_lcd::LoadDatabase merge;
  merge.request.path = "large.mild";
  merge.request.merge = true;
  std::thread merging([&] { EXPECT_TRUE(ros::service::call("/load_database", merge)); });
  ros::WallDuration(1.0).sleep();  // the file is read; the merge rebuilds the index, holding the detector

  dynamic_reconfigure::Reconfigure retune;
  dynamic_reconfigure::IntParameter candidates;
  candidates.name = "detector_max_candidates";
  candidates.value = 1;
  retune.request.config.ints.push_back(candidates);
  EXPECT_TRUE(ros::service::call("/mild_lcd/tuning/set_parameters", retune));
  merging.join();
  stream.join();
  EXPECT_TRUE(merge.response.success) << merge.response.message;
  EXPECT_GE(merge.response.keyframes, 3000u);
  int max_candidates = -1;
  for (const auto& p : retune.response.config.ints) {
    if (p.name == "detector_max_candidates") max_candidates = p.value;
  }
  EXPECT_EQ(max_candidates, 1) << "the retune is applied";

  // Until everything sent is accounted for, or long after it should have been.
  long answered = 0, dropped = 0, rejected = 0, discarded = 0;
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(60.0);
  while (ros::WallTime::now() < end) {
    answered = static_cast<long>(outputs.size());
    dropped = counters.counted("dropped keyframes");
    rejected = counters.counted("rejected keyframes");
    discarded = counters.counted("discarded keyframes");
    if (answered + dropped + rejected + discarded == kSent && counters.counted("queue depth") == 0) break;
    ros::WallDuration(0.2).sleep();
  }
  EXPECT_EQ(answered + dropped + rejected + discarded, kSent)
      << answered << " answered, " << dropped << " dropped, " << rejected << " rejected, " << discarded
      << " discarded of " << kSent << " sent";
  EXPECT_EQ(rejected, 0);
  RecordProperty("accounted", std::to_string(answered) + " answered, " + std::to_string(dropped) + " dropped, " +
                                  std::to_string(rejected) + " rejected, " + std::to_string(discarded) + " discarded");
  fs::remove_all(busyDir());
}

}  // namespace
}  // namespace mild_lcd::test
