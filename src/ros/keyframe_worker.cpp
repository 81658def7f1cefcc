#include "mild_lcd/ros/keyframe_worker.hpp"

#include <malloc.h>

#include "mild_lcd/common/errors.hpp"

namespace mild_lcd {

KeyframeWorker::KeyframeWorker(SharedDetector& shared, size_t queue_size, uint64_t max_image_pixels, Hooks hooks)
    : shared_(shared), queue_(queue_size), max_image_pixels_(max_image_pixels), hooks_(std::move(hooks)) {}

KeyframeWorker::~KeyframeWorker() { stop(); }

void KeyframeWorker::start() {
  if (!thread_.joinable()) thread_ = std::thread([this] { run(); });
}

bool KeyframeWorker::push(KeyframeInput input) { return queue_.push(std::move(input)); }

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
    process(*item);
    queue_.done();
  }
}

void KeyframeWorker::refreshSnapshot(const mild::LoopDetector& detector) {
  std::lock_guard<std::mutex> lock(stats_mutex_);
  stats_.keyframes = detector.size();
  stats_.features = detector.database().featureCount();
  stats_.memory_bytes = detector.memoryBytes();
  stats_.discarded_buckets = detector.database().index().discardedBuckets();
}

void KeyframeWorker::process(const KeyframeInput& input) {
  ProcessedKeyframe out;
  try {
    out.header = input.image        ? input.image->header
                 : input.compressed ? input.compressed->header
                                    : input.keyframe->header;
    std::optional<uint64_t> id;
    mild::Features features;
    if (input.image || input.compressed) {
      out.image = input.image ? imageFromMsg(*input.image, max_image_pixels_)
                              : imageFromMsg(*input.compressed, max_image_pixels_);
    } else {
      if (input.keyframe->has_id) id = input.keyframe->id;
      features = featuresFromMsg(*input.keyframe);
    }
    const bool keypoints = hooks_.wants_keypoints && hooks_.wants_keypoints();
    std::lock_guard<std::mutex> lock(shared_.mutex);
    if (!shared_.failure.empty()) throw mild::InvalidInput(shared_.failure);
    // Only this call changes the detector; it throws before changing anything.
    out.result = out.image.image.empty()
                     ? shared_.detector->process(std::move(features), out.header.stamp.toSec(), id)
                     : shared_.detector->process(out.image.image, out.image.format, out.header.stamp.toSec(),
                                                 std::nullopt, input.camera);
    out.database_size = shared_.detector->size();
    if (keypoints) {
      out.query_keypoints = shared_.detector->record(out.result.query_index).keypoints;
      if (!out.result.candidates.empty()) {
        out.candidate_keypoints = shared_.detector->record(out.result.candidates.front().index).keypoints;
      }
    }
    // memoryBytes() walks every keyframe: once a second.
    const auto now = std::chrono::steady_clock::now();
    if (now >= next_snapshot_) {
      refreshSnapshot(*shared_.detector);
      next_snapshot_ = now + std::chrono::seconds(1);
      // The index's arrays grow by reallocation; glibc keeps the smaller copies they leave behind,
      // and the process would grow about 2.5 times as fast as the map. Handing free pages back once
      // a second rather than after every merge: a trim walks the whole heap (per merge, inserting
      // became four times slower).
      malloc_trim(0);
    }
  } catch (const std::exception& e) {
    {
      std::lock_guard<std::mutex> lock(stats_mutex_);
      ++stats_.rejected;
    }
    if (hooks_.warn) {
      hooks_.warn("rejected keyframe (stamp " + std::to_string(out.header.stamp.toSec()) + "): " + e.what());
    }
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
  return c;
}

}  // namespace mild_lcd
