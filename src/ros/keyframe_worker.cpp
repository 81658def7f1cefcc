#include "mild_lcd/ros/keyframe_worker.hpp"

#include <malloc.h>

#include "mild_lcd/common/errors.hpp"

namespace mild_lcd {

KeyframeWorker::KeyframeWorker(SharedDetector& shared, size_t queue_size, size_t queue_bytes, const InputLimits& limits,
                               Hooks hooks)
    : shared_(shared), queue_(queue_size, queue_bytes), limits_(limits), hooks_(std::move(hooks)) {}

KeyframeWorker::~KeyframeWorker() { stop(); }

void KeyframeWorker::start() {
  if (!thread_.joinable()) thread_ = std::thread([this] { run(); });
}

KeyframeWorker::Pushed KeyframeWorker::push(KeyframeInputPtr input) {
  size_t bytes = 0;
  try {
    bytes = input->checkedBytes(limits_);
    if (bytes > queue_.capacityBytes()) {
      throw mild::InvalidInput("a message of " + std::to_string(bytes) + " bytes is larger than the whole queue (" +
                               std::to_string(queue_.capacityBytes()) + " bytes, ~queue_mb)");
    }
  } catch (const std::exception& e) {
    reject(input->header(), e.what());
    return Pushed::kRejected;  // the message is released as this returns
  }
  return queue_.push(std::move(input), bytes) ? Pushed::kQueued : Pushed::kDroppedOldest;
}

void KeyframeWorker::reject(const std_msgs::Header& header, const std::string& why) {
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.rejected;
  }
  if (hooks_.warn) hooks_.warn("rejected keyframe (stamp " + std::to_string(header.stamp.toSec()) + "): " + why);
}

size_t KeyframeWorker::discardPending() {
  const size_t n = queue_.clear();
  discarded_ += n;
  return n;
}

void KeyframeWorker::stop() {
  queue_.close();
  discardPending();
  if (thread_.joinable()) thread_.join();
}

void KeyframeWorker::run() {
  if (hooks_.startup) {
    try {
      hooks_.startup();
    } catch (const std::exception&) {
      // The hook has logged and recorded the failure (shared_.failure): keyframes are refused from
      // now on, saying why.
    }
  }
  while (auto item = queue_.pop()) {
    process(**item);
    queue_.done();
  }
}

void KeyframeWorker::refreshSnapshot(const mild::RobotTeam& team) {
  size_t discarded_buckets = 0;
  for (size_t r = 0; r < team.size(); ++r) discarded_buckets += team.robot(r).database().index().discardedBuckets();
  std::lock_guard<std::mutex> lock(stats_mutex_);
  stats_.keyframes = team.keyframes();
  stats_.features = team.features();
  stats_.memory_bytes = team.memoryBytes();
  stats_.discarded_buckets = discarded_buckets;
}

void KeyframeWorker::process(const KeyframeInput& input) {
  ProcessedKeyframe out;
  try {
    out.header = input.header();
    mild::Observation observation = input.observe(limits_, out.image);
    const size_t robot = observation.robot;
    const bool keypoints = hooks_.wants_keypoints && hooks_.wants_keypoints();
    const auto lock = shared_.lock();
    mild::RobotTeam& team = *shared_.team;
    if (robot < shared_.failure.size() && !shared_.failure[robot].empty()) {
      throw mild::InvalidInput(shared_.failure[robot]);
    }
    // Only this call changes the detector; it throws before changing anything.
    out.result = team.process(std::move(observation));
    ++shared_.changes;
    out.database_size = team.robot(robot).size();
    if (keypoints) {
      out.query_keypoints = team.robot(robot).record(out.result.query_index).keypoints;
      if (!out.result.candidates.empty()) {
        const mild::LoopCandidate& best = out.result.candidates.front();
        out.candidate_keypoints = team.robot(best.robot).record(best.index).keypoints;
      }
    }
    // memoryBytes() walks every keyframe: once a second.
    const auto now = std::chrono::steady_clock::now();
    if (now >= next_snapshot_) {
      refreshSnapshot(team);
      next_snapshot_ = now + std::chrono::seconds(1);
      // The index's arrays grow by reallocation; glibc keeps the smaller copies they leave behind,
      // and the process would grow about 2.5 times as fast as the map. Handing free pages back once
      // a second rather than after every merge: a trim walks the whole heap (per merge, inserting
      // became four times slower).
      malloc_trim(0);
    }
  } catch (const std::exception& e) {
    reject(out.header, e.what());
    return;
  }
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    ++stats_.processed;
    const auto& s = out.result.stats;
    stats_.last_ms = s.extract_ms + s.query_ms + s.filter_ms + s.verify_ms;
    stats_.last_query_ms = s.query_ms;
    total_ms_ += stats_.last_ms;
    total_query_ms_ += s.query_ms;
    stats_.mean_ms = total_ms_ / static_cast<double>(stats_.processed);
    stats_.mean_query_ms = total_query_ms_ / static_cast<double>(stats_.processed);
  }
  // Publishing and drawing happen outside the detector lock; their failures are theirs, not the
  // keyframe's: it is stored and answered already.
  try {
    if (hooks_.publish) hooks_.publish(out);
  } catch (const std::exception& e) {
    if (hooks_.warn) hooks_.warn(std::string("publishing a result failed: ") + e.what());
  }
}

WorkerCounters KeyframeWorker::counters() const {
  WorkerCounters c;
  {
    std::lock_guard<std::mutex> lock(stats_mutex_);
    c = stats_;
  }
  c.dropped = queue_.dropped();
  c.discarded = discarded_.load();
  c.queued = queue_.size();
  c.capacity = queue_.capacity();
  c.queued_bytes = queue_.bytes();
  c.capacity_bytes = queue_.capacityBytes();
  return c;
}

}  // namespace mild_lcd
