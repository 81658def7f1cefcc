#include "mild_lcd/ros/detection/periodic_task.hpp"

namespace mild_lcd {

PeriodicTask::PeriodicTask(std::chrono::milliseconds period, std::function<void()> task) {
  thread_ = std::thread([this, period, task = std::move(task)] {
    std::unique_lock<std::mutex> lock(mutex_);
    auto next = std::chrono::steady_clock::now() + period;
    while (!wake_.wait_until(lock, next, [this] { return stop_; })) {
      lock.unlock();
      task();
      lock.lock();
      next = std::chrono::steady_clock::now() + period;  // a slow run never makes the next one come sooner
    }
  });
}

PeriodicTask::~PeriodicTask() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

}  // namespace mild_lcd
