#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>

namespace mild {

// A bounded multi-producer queue drained by one worker, bounded in items and in bytes (each item's
// size as its producer states it). When full, push() drops the oldest waiting items (like a ROS
// subscriber queue) until the new one fits, and counts them, so that callbacks never block and no
// drop goes unnoticed.
template <class T>
class BoundedQueue {
 public:
  explicit BoundedQueue(size_t capacity, size_t capacity_bytes = SIZE_MAX)
      : capacity_(capacity == 0 ? 1 : capacity), capacity_bytes_(capacity_bytes) {}

  // Returns false when older items had to be dropped to make room. An item of more than
  // capacity_bytes on its own is the caller's to refuse: it would be kept alone. After close() the
  // item is discarded (and counted as dropped).
  bool push(T item, size_t bytes = 0) {
    bool kept_all = true;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (closed_) {
        ++dropped_;
        return false;
      }
      while (!items_.empty() &&
             (items_.size() >= capacity_ || bytes_ > capacity_bytes_ || bytes > capacity_bytes_ - bytes_)) {
        bytes_ -= items_.front().bytes;
        items_.pop_front();
        ++dropped_;
        kept_all = false;
      }
      items_.push_back({std::move(item), bytes});
      bytes_ += bytes;
    }
    ready_.notify_one();
    return kept_all;
  }

  // Blocks until an item is available; nullopt once the queue is closed and empty.
  std::optional<T> pop() {
    std::unique_lock<std::mutex> lock(mutex_);
    ready_.wait(lock, [this] { return closed_ || !items_.empty(); });
    if (items_.empty()) return std::nullopt;
    T item = std::move(items_.front().item);
    bytes_ -= items_.front().bytes;
    items_.pop_front();
    ++busy_;
    return item;
  }

  // The worker calls this when it has finished the item pop() gave it; waitIdle() waits for it.
  void done() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (busy_ > 0) --busy_;
    }
    idle_.notify_all();
  }

  // Blocks until nothing is queued or being processed.
  void waitIdle() {
    std::unique_lock<std::mutex> lock(mutex_);
    idle_.wait(lock, [this] { return items_.empty() && busy_ == 0; });
  }

  // Wakes the worker; later pushes are discarded.
  void close() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
  }

  // Removes everything waiting; returns how many items that was (not counted as dropped).
  size_t clear() {
    std::lock_guard<std::mutex> lock(mutex_);
    const size_t n = items_.size();
    items_.clear();
    bytes_ = 0;
    idle_.notify_all();
    return n;
  }

  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return items_.size();
  }
  size_t dropped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_;
  }
  // The bytes of the items waiting, as their producers stated them.
  size_t bytes() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return bytes_;
  }
  size_t capacity() const { return capacity_; }
  size_t capacityBytes() const { return capacity_bytes_; }

 private:
  struct Entry {
    T item;
    size_t bytes;
  };

  const size_t capacity_;
  const size_t capacity_bytes_;
  mutable std::mutex mutex_;
  std::condition_variable ready_, idle_;
  std::deque<Entry> items_;
  size_t bytes_ = 0;
  size_t dropped_ = 0;
  size_t busy_ = 0;
  bool closed_ = false;
};

}  // namespace mild
