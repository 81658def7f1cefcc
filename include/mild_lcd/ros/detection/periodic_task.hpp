#pragma once

// Runs a function every `period` on a thread of its own until destroyed (the nodelet's periodic
// save of its map, ~autosave_period). ROS-free.

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>

namespace mild_lcd {

class PeriodicTask {
 public:
  // `task` runs first one period after construction; its exceptions are its own to handle.
  PeriodicTask(std::chrono::milliseconds period, std::function<void()> task);
  // Waits for a run in progress, then stops.
  ~PeriodicTask();
  PeriodicTask(const PeriodicTask&) = delete;
  PeriodicTask& operator=(const PeriodicTask&) = delete;

 private:
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace mild_lcd
