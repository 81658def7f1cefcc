#pragma once

#include <memory>
#include <mutex>
#include <string>

#include "mild_lcd/detector/loop_detector.hpp"

namespace mild_lcd {

// The detector and the lock every user takes: the worker for one keyframe at a time, services for
// as little as they can (copying features, swapping a prepared map in). Nothing slow is done while
// holding it except a save, which streams the state to disk.
struct SharedDetector {
  std::mutex mutex;
  std::unique_ptr<mild::LoopDetector> detector;
  // Set when the map named at start-up could not be loaded: keyframes and services are refused
  // (saying why), so that nothing is learnt on an empty map that a save could then write over it.
  std::string failure;  // under mutex
};

}  // namespace mild_lcd
