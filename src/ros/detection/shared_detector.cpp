#include "mild_lcd/ros/detection/shared_detector.hpp"

#include <ros/console.h>

namespace mild_lcd {

void SharedDetector::mapReplaced(size_t robot, bool unsaved) {
  team->mapChanged(robot);
  ++replaced;
  if (unsaved) ++changes;
  if (on_map_replaced) on_map_replaced(robot);
}

void SharedDetector::resetMaps() {
  team->reset();
  ++replaced;
  ++changes;
  if (on_map_replaced) {
    for (size_t r = 0; r < team->size(); ++r) on_map_replaced(r);
  }
}

std::unique_lock<std::mutex> SharedDetector::lock() {
  std::unique_lock<std::mutex> held(mutex);
  applyPendingRetune();
  return held;
}

std::unique_lock<std::mutex> SharedDetector::tryLock() {
  std::unique_lock<std::mutex> held(mutex, std::try_to_lock);
  if (held.owns_lock()) applyPendingRetune();
  return held;
}

void SharedDetector::requestRetune(const mild::DetectorParams& next) {
  {
    std::lock_guard<std::mutex> pending(retune_mutex_);
    pending_retune_ = next;
  }
  tryLock();  // applies it now unless the detector is busy; then its holder does, when done
}

bool SharedDetector::retunePending() {
  std::lock_guard<std::mutex> pending(retune_mutex_);
  return pending_retune_.has_value();
}

void SharedDetector::applyPendingRetune() {
  std::optional<mild::DetectorParams> next;
  {
    std::lock_guard<std::mutex> pending(retune_mutex_);
    next.swap(pending_retune_);
  }
  if (!next || !team) return;
  try {
    team->retune(*next);
  } catch (const std::exception& e) {
    // Not reached: the caller validated the values and changed only runtime parameters. Said
    // anyway rather than lost.
    ROS_ERROR_STREAM("mild_lcd: a validated retune was refused, values kept: " << e.what());
  }
}

}  // namespace mild_lcd
