#pragma once

// The one thread that runs the detector: subscriber callbacks push keyframes into a queue bounded
// in keyframes and in bytes (never blocking a nodelet manager thread), the worker decodes and
// processes them in arrival order, and hands each result to `publish` outside the detector lock.
// Every keyframe that arrives is answered, or counted: dropped (queue full), rejected (unusable,
// or over its size bounds, judged as it is pushed), or discarded (reset, shutdown).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "mild_lcd/ros/bounded_queue.hpp"
#include "mild_lcd/ros/conversions.hpp"
#include "mild_lcd/ros/keyframe_input.hpp"
#include "mild_lcd/ros/shared_detector.hpp"

namespace mild_lcd {

// One processed keyframe, for the publishers.
struct ProcessedKeyframe {
  std_msgs::Header header;
  mild::DetectionResult result;                   // result.query_robot: whose keyframe it was
  size_t database_size = 0;                       // of that robot's map
  DecodedImage image;                             // empty for keyframe (feature) input
  std::vector<cv::KeyPoint> query_keypoints;      // filled when `wants_keypoints` said so
  std::vector<cv::KeyPoint> candidate_keypoints;  // of the best candidate, likewise
};

struct WorkerCounters {
  size_t processed = 0, rejected = 0, dropped = 0, discarded = 0, queued = 0, capacity = 0;
  size_t queued_bytes = 0, capacity_bytes = 0;
  double last_ms = 0.0, mean_ms = 0.0, last_query_ms = 0.0, mean_query_ms = 0.0;
  size_t keyframes = 0, features = 0, memory_bytes = 0, discarded_buckets = 0;  // database snapshot
};

class KeyframeWorker {
 public:
  struct Hooks {
    std::function<void()> startup;                          // runs first, on the worker thread
    std::function<void(const ProcessedKeyframe&)> publish;  // after each keyframe, unlocked
    std::function<bool()> wants_keypoints;                  // copy keypoints for the debug image?
    std::function<void(const std::string&)> warn;           // throttling is the caller's
  };
  // The queue holds at most queue_size keyframes and queue_bytes bytes of messages.
  KeyframeWorker(SharedDetector& shared, size_t queue_size, size_t queue_bytes, const InputLimits& limits, Hooks hooks);
  ~KeyframeWorker();

  void start();
  enum class Pushed { kQueued, kDroppedOldest, kRejected };
  // From any thread; never waits for the detector. A message over its size bounds (InputLimits, or
  // larger than the whole queue) is rejected, counted and warned about here, and released at once;
  // kDroppedOldest: older keyframes were dropped to make room.
  Pushed push(KeyframeInputPtr input);
  // Removes every waiting keyframe and counts it as discarded; returns how many.
  size_t discardPending();
  // Discards what waits, lets the keyframe in progress finish, and joins the thread.
  void stop();
  // Blocks until nothing waits or is in progress (tests).
  void waitIdle() { queue_.waitIdle(); }

  WorkerCounters counters() const;
  // Takes the database figures of diagnostics from the team (under its lock).
  void refreshSnapshot(const mild::RobotTeam& team);

 private:
  void run();
  void process(const KeyframeInput& input);
  void reject(const std_msgs::Header& header, const std::string& why);

  SharedDetector& shared_;
  mild::BoundedQueue<KeyframeInputPtr> queue_;
  const InputLimits limits_;
  Hooks hooks_;
  std::thread thread_;
  std::atomic<size_t> discarded_{0};

  mutable std::mutex stats_mutex_;
  WorkerCounters stats_;  // processed, rejected, timings, snapshot
  double total_ms_ = 0.0, total_query_ms_ = 0.0;
  std::chrono::steady_clock::time_point next_snapshot_{};
};

}  // namespace mild_lcd
