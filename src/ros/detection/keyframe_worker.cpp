#include "mild_lcd/ros/detection/keyframe_worker.hpp"

#include <malloc.h>

#include <sstream>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"

namespace mild_lcd {

KeyframeWorker::KeyframeWorker(SharedDetector& shared, size_t queue_size, size_t queue_bytes, const InputLimits& limits,
                               Hooks hooks, bool extraction_thread)
    : shared_(shared),
      queue_(queue_size, queue_bytes),
      limits_(limits),
      hooks_(std::move(hooks)),
      pipelined_(extraction_thread) {}

KeyframeWorker::~KeyframeWorker() { stop(); }

void KeyframeWorker::start() {
  if (thread_.joinable()) return;
  // The front-end is built once, from the team's own features/ parameters: they are start-up
  // parameters (retune refuses them), a load, merge or reset replaces a map but not its
  // parameters, every robot of a team has the same ones, and the team outlives the worker (the
  // nodelet builds it first).
  mild::FeatureParams features;
  {
    const auto lock = shared_.lock();
    features = shared_.team->params().features;
  }
  front_end_ = std::make_unique<mild::FeatureFrontEnd>(features);
  if (!pipelined_) {
    thread_ = std::thread([this] { runOneThread(); });
    return;
  }
  thread_ = std::thread([this] { runDetector(); });
  extraction_thread_ = std::thread([this] { runExtraction(); });
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

size_t KeyframeWorker::discardHandoff() {
  std::optional<Staged> discarded;  // released outside the lock
  {
    std::lock_guard<std::mutex> lock(handoff_mutex_);
    discarded.swap(handoff_);
  }
  handoff_changed_.notify_all();
  if (!discarded) return 0;
  ++discarded_;
  queue_.done();
  return 1;
}

size_t KeyframeWorker::discardPending() {
  const size_t n = queue_.clear();
  discarded_ += n;
  return n + discardHandoff();
}

void KeyframeWorker::stop() {
  // Once stopping_ is set, stage 1 hands nothing over (it counts what it holds as discarded) and
  // stage 2 takes nothing more: discardPending below empties the hand-off for good.
  {
    std::lock_guard<std::mutex> lock(handoff_mutex_);
    stopping_ = true;
  }
  handoff_changed_.notify_all();
  queue_.close();
  discardPending();
  if (extraction_thread_.joinable()) extraction_thread_.join();
  if (thread_.joinable()) thread_.join();
}

void KeyframeWorker::startup() {
  if (!hooks_.startup) return;
  try {
    hooks_.startup();
  } catch (const std::exception&) {
    // The hook has logged and recorded the failure (shared_.failure): keyframes are refused from
    // now on, saying why.
  }
}

void KeyframeWorker::runOneThread() {
  startup();
  while (auto item = queue_.pop()) {
    process(stage(std::move(*item)));
    queue_.done();
  }
}

void KeyframeWorker::runExtraction() {
  for (;;) {
    {
      // The next keyframe is popped once the previous one has gone to the detector: one at most waits
      // extracted, the rest stay in the queue, where its bounds apply (and the oldest is dropped).
      std::unique_lock<std::mutex> lock(handoff_mutex_);
      handoff_changed_.wait(lock, [this] { return stopping_ || !handoff_; });
      if (stopping_) break;
    }
    std::optional<KeyframeInputPtr> item = queue_.pop();
    if (!item) break;
    Staged staged = stage(std::move(*item));
    {
      std::lock_guard<std::mutex> lock(handoff_mutex_);
      if (!stopping_) {
        handoff_ = std::move(staged);
        handoff_changed_.notify_all();
        continue;
      }
    }
    ++discarded_;  // stop() came while it was extracted
    queue_.done();
    break;
  }
  {
    std::lock_guard<std::mutex> lock(handoff_mutex_);
    extraction_done_ = true;
  }
  handoff_changed_.notify_all();
}

void KeyframeWorker::runDetector() {
  startup();
  for (;;) {
    std::optional<Staged> staged;
    {
      std::unique_lock<std::mutex> lock(handoff_mutex_);
      handoff_changed_.wait(lock, [this] { return stopping_ || handoff_ || extraction_done_; });
      if (stopping_ || !handoff_) break;
      staged.swap(handoff_);
    }
    handoff_changed_.notify_all();  // stage 1 may take the next keyframe
    process(std::move(*staged));
    queue_.done();
  }
}

KeyframeWorker::Staged KeyframeWorker::stage(KeyframeInputPtr input) const {
  Staged staged;
  staged.header = input->header();
  try {
    staged.observation = front_end_->extract(input->observe(limits_, staged.image));
  } catch (const std::exception& e) {
    staged.observation.reset();
    staged.error = e.what();
  }
  staged.input = std::move(input);  // the decoded image may point into the message
  if (hooks_.staged) hooks_.staged(staged.header, staged.observation.has_value());
  return staged;
}

void KeyframeWorker::refreshSnapshot(const mild::RobotTeam& team) {
  size_t discarded_buckets = 0;
  for (size_t r = 0; r < team.size(); ++r)
    discarded_buckets += team.robot(r).map().database().index().discardedBuckets();
  std::lock_guard<std::mutex> lock(stats_mutex_);
  stats_.keyframes = team.keyframes();
  stats_.features = team.features();
  stats_.memory_bytes = team.memoryBytes();
  stats_.discarded_buckets = discarded_buckets;
}

void KeyframeWorker::process(Staged staged) {
  ProcessedKeyframe out;
  out.header = staged.header;
  out.image = std::move(staged.image);
  if (!staged.observation) {
    reject(out.header, staged.error);
    return;
  }
  try {
    mild::Observation observation = std::move(*staged.observation);
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
    if (hooks_.stored) hooks_.stored(out.result);
    out.database_size = team.robot(robot).map().size();
    if (keypoints) {
      out.query_keypoints = team.robot(robot).map().record(out.result.query_index).keypoints;
      if (!out.result.candidates.empty()) {
        const mild::LoopCandidate& best = out.result.candidates.front();
        out.candidate_keypoints = team.robot(best.robot).map().record(best.index).keypoints;
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
    stats_.depths_out_of_range += s.depths_out_of_range;
    stats_.clock_steps_back += s.clock_stepped_back ? 1 : 0;
  }
  if (out.result.stats.clock_stepped_back && hooks_.warn) {
    hooks_.warn("keyframe (stamp " + std::to_string(out.header.stamp.toSec()) +
                ") is stamped before the previous one: the clock stepped back (a replay restarted?); counted as no "
                "time passing for detector/exclusion_seconds");
  }
  if (out.result.stats.depths_out_of_range > 0 && hooks_.warn) {
    std::ostringstream what;
    what << "keyframe (stamp " << out.header.stamp.toSec() << "): " << out.result.stats.depths_out_of_range
         << " depths outside [" << mild::kMinDepthMetres << ", " << mild::kMaxDepthMetres
         << "] m taken as unknown (a unit or scale error upstream?)";
    hooks_.warn(what.str());
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
  {
    std::lock_guard<std::mutex> lock(handoff_mutex_);
    c.handed_over = handoff_ ? 1 : 0;
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
