#pragma once

// The worker that runs the detector: subscriber callbacks push keyframes into a queue bounded in
// keyframes and in bytes (never blocking a nodelet manager thread), the worker decodes and
// processes them in arrival order, and hands each result to `publish` outside the detector lock.
// Every keyframe that arrives is answered, or counted: dropped (queue full), rejected (unusable,
// or over its size bounds, judged as it is pushed), or discarded (reset, shutdown).
//
// The worker owns the one feature front-end (mild::FeatureFrontEnd) that turns images into
// features: the detector takes features only, so an image is extracted once, never under the lock.
// Two stages, on two threads when `extraction_thread` (~extraction_thread): stage 1 decodes the
// next keyframe and extracts its features without the detector lock while
// stage 2 queries, filters, verifies and inserts the previous one under the lock, then publishes.
// One keyframe at most waits between them (the hand-off), and stage 1 pops the next only once the
// hand-off is empty: besides what the queue's bounds allow, at most two keyframes are held, one per
// stage. Answers keep the arrival order: stage 2 takes keyframes, refused ones included, in the
// order stage 1 popped them. Without it, one thread decodes and extracts a keyframe, then takes the
// lock for the detector.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "mild_lcd/detector/feature_front_end.hpp"
#include "mild_lcd/ros/detection/bounded_queue.hpp"
#include "mild_lcd/ros/detection/shared_detector.hpp"
#include "mild_lcd/ros/input/image_decoding.hpp"
#include "mild_lcd/ros/input/input_admission.hpp"
#include "mild_lcd/ros/input/keyframe_input.hpp"

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
  size_t handed_over = 0;  // out of the queue, extracted, waiting for the detector (0 or 1)
  size_t queued_bytes = 0, capacity_bytes = 0;
  double last_ms = 0.0, mean_ms = 0.0, last_query_ms = 0.0, mean_query_ms = 0.0;
  size_t keyframes = 0, features = 0, memory_bytes = 0, discarded_buckets = 0;  // database snapshot
  // Of the answered keyframes: depths taken as unknown for being out of range, and those stamped
  // below the previous keyframe of their session (StepStats).
  size_t depths_out_of_range = 0, clock_steps_back = 0;
};

class KeyframeWorker {
 public:
  struct Hooks {
    std::function<void()> startup;                          // runs first, on the worker thread
    std::function<void(const ProcessedKeyframe&)> publish;  // after each keyframe, unlocked
    // Right after a keyframe was stored, still under the detector lock (the team across hosts
    // numbers it in the order the maps grow). Must not throw.
    std::function<void(const mild::DetectionResult&)> stored;
    std::function<bool()> wants_keypoints;         // copy keypoints for the debug image?
    std::function<void(const std::string&)> warn;  // throttling is the caller's
    // A keyframe is ready for the detector: decoded and, with the extraction thread, its features
    // extracted (or it was found unusable); on the thread that did it, before the detector sees it.
    // has_features: its features are known (extracted, or they came as such). For tests: whether
    // extraction overlaps the previous keyframe's processing. Must not throw.
    std::function<void(const std_msgs::Header&, bool has_features)> staged;
  };
  // The queue holds at most queue_size keyframes and queue_bytes bytes of messages.
  // extraction_thread: decode and extract on a thread of its own, one keyframe ahead of the
  // detector (the caller decides whether the machine has a core for it); false: one thread.
  KeyframeWorker(SharedDetector& shared, size_t queue_size, size_t queue_bytes, const InputLimits& limits, Hooks hooks,
                 bool extraction_thread = true);
  ~KeyframeWorker();

  // Starts the thread(s). The team must exist: the front-end is built from its features/ parameters
  // here.
  void start();
  enum class Pushed { kQueued, kDroppedOldest, kRejected };
  // From any thread; never waits for the detector. A message over its size bounds (InputLimits, or
  // larger than the whole queue) is rejected, counted and warned about here, and released at once;
  // kDroppedOldest: older keyframes were dropped to make room.
  Pushed push(KeyframeInputPtr input);
  // Removes every waiting keyframe, the one extracted and waiting for the detector included, and
  // counts it as discarded; returns how many. The keyframe each stage is working on goes on.
  size_t discardPending();
  // Discards what waits and what stage 1 holds, lets the keyframe the detector has finish, and
  // joins the thread(s).
  void stop();
  // Blocks until nothing waits or is in progress in either stage (tests).
  void waitIdle() { queue_.waitIdle(); }

  // Whether keyframes are extracted on a thread of their own (started with one).
  bool extractionThread() const { return pipelined_; }
  WorkerCounters counters() const;
  // Takes the database figures of diagnostics from the team (under its lock).
  void refreshSnapshot(const mild::RobotTeam& team);

 private:
  // A keyframe through stage 1: its message (decoded images may point into it), the decoded image,
  // and its observation with its features; or why it is refused.
  struct Staged {
    KeyframeInputPtr input;
    std_msgs::Header header;
    DecodedImage image;
    std::optional<mild::Observation> observation;  // empty: refused, `error` says why
    std::string error;
  };

  void runOneThread();
  void runExtraction();  // stage 1, on extraction_thread_
  void runDetector();    // stage 2
  void startup();
  // Stage 1: decodes and extracts.
  Staged stage(KeyframeInputPtr input) const;
  // Stage 2: the detector, under its lock, then publishing.
  void process(Staged staged);
  void reject(const std_msgs::Header& header, const std::string& why);
  size_t discardHandoff();  // the hand-off's keyframe, if any; returns how many (0 or 1)

  SharedDetector& shared_;
  mild::BoundedQueue<KeyframeInputPtr> queue_;  // busy (waitIdle) from pop until stage 2 is done
  const InputLimits limits_;
  Hooks hooks_;
  const bool pipelined_;           // extraction_thread
  std::thread thread_;             // stage 2, or the one thread
  std::thread extraction_thread_;  // stage 1
  std::atomic<size_t> discarded_{0};

  // The worker's feature front-end, used by stage 1 only (extractors are not thread-safe).
  std::unique_ptr<mild::FeatureFrontEnd> front_end_;

  mutable std::mutex handoff_mutex_;
  std::condition_variable handoff_changed_;
  std::optional<Staged> handoff_;  // at most one keyframe between the stages
  bool stopping_ = false;          // stop(): neither stage takes another keyframe
  bool extraction_done_ = false;   // stage 1 has left (the queue closed)

  mutable std::mutex stats_mutex_;
  WorkerCounters stats_;  // processed, rejected, timings, snapshot
  double total_ms_ = 0.0, total_query_ms_ = 0.0;
  std::chrono::steady_clock::time_point next_snapshot_{};
};

}  // namespace mild_lcd
