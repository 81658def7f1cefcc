#include "mild_lcd/ros/output/detector_diagnostics.hpp"

namespace mild_lcd {

DetectorDiagnostics::DetectorDiagnostics(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name,
                                         SharedDetector& shared, KeyframeWorker& worker)
    : shared_(shared), worker_(worker) {
  updater_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, name);
  updater_->setHardwareID("mild_lcd");
  updater_->add("loop closure detector", this, &DetectorDiagnostics::diagnose);
  timer_ = nh.createWallTimer(ros::WallDuration(0.5), [this](const ros::WallTimerEvent&) { updater_->update(); });
}

void DetectorDiagnostics::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  {
    // Never wait for a keyframe in progress: a busy worker refreshes the snapshot itself.
    const auto lock = shared_.tryLock();
    if (lock.owns_lock()) {
      worker_.refreshSnapshot(*shared_.team);
      failure_.clear();
      for (size_t r = 0; r < shared_.failure.size(); ++r) {
        if (shared_.failure[r].empty()) continue;
        const std::string& name = shared_.team->name(r);
        failure_ += (failure_.empty() ? "" : "; ") + (name.empty() ? "" : name + ": ") + shared_.failure[r];
      }
      robots_ = shared_.team->size();
    }
  }
  const WorkerCounters c = worker_.counters();
  if (!failure_.empty()) {
    status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, failure_);
  } else if (c.dropped > reported_dropped_ || c.rejected > reported_rejected_) {
    status.summaryf(diagnostic_msgs::DiagnosticStatus::WARN, "%zu dropped, %zu rejected keyframes since start",
                    c.dropped, c.rejected);
  } else {
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "running");
  }
  reported_dropped_ = c.dropped;
  reported_rejected_ = c.rejected;
  if (robots_ > 1) status.add("robots", robots_);
  status.add("database keyframes", c.keyframes);
  status.add("database features", c.features);
  status.add("memory (MB)", static_cast<double>(c.memory_bytes) / 1e6);
  status.add("discarded buckets", c.discarded_buckets);
  status.add("processed keyframes", c.processed);
  status.add("queue depth", c.queued);
  status.add("queue capacity", c.capacity);
  status.add("queue (MB)", static_cast<double>(c.queued_bytes) / 1e6);
  status.add("queue capacity (MB)", static_cast<double>(c.capacity_bytes) / 1e6);
  status.add("dropped keyframes", c.dropped);
  status.add("rejected keyframes", c.rejected);
  status.add("discarded keyframes", c.discarded);
  status.add("depths out of range", c.depths_out_of_range);
  status.add("clock steps back", c.clock_steps_back);
  status.add("last query (ms)", c.last_query_ms);
  status.add("mean query (ms)", c.mean_query_ms);
  status.add("last keyframe (ms)", c.last_ms);
  status.add("mean keyframe (ms)", c.mean_ms);
}

void DetectorDiagnostics::add(const std::string& name,
                              std::function<void(diagnostic_updater::DiagnosticStatusWrapper&)> task) {
  updater_->add(name, std::move(task));
}

}  // namespace mild_lcd
