#pragma once

// What `debug_image` shows: the query and its best candidate side by side with the inlier matches
// the detector's own verification found (nothing is matched again). ROS-free.

#include <cstdint>
#include <deque>
#include <mutex>
#include <unordered_map>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/features/features.hpp"

namespace mild_lcd {

// Half-resolution grey copies of the latest keyframes, bounded in count and in bytes. A keyframe is
// named by its robot (the index in the team; ids of two robots may coincide) and its id.
class DebugImageCache {
 public:
  DebugImageCache(size_t max_images, size_t max_bytes) : max_images_(max_images), max_bytes_(max_bytes) {}

  // Keeps a copy of `image` (of the given channel order) under (robot, id).
  void remember(uint64_t id, const cv::Mat& image, mild::PixelFormat format, uint32_t robot = 0);
  // Empty when not (or no longer) cached.
  cv::Mat find(uint64_t id, uint32_t robot = 0) const;
  void clear();
  void clear(uint32_t robot);  // one robot's, after its map was replaced
  size_t bytes() const;
  size_t size() const;

 private:
  void evict();
  const size_t max_images_;
  const size_t max_bytes_;
  mutable std::mutex mutex_;
  using Key = std::pair<uint32_t, uint64_t>;  // robot, id
  struct KeyHash {
    size_t operator()(const Key& k) const { return std::hash<uint64_t>()(k.second * 31 + k.first); }
  };
  std::unordered_map<Key, cv::Mat, KeyHash> images_;
  std::deque<Key> order_;
  size_t bytes_ = 0;
};

// The picture: query (left) and best candidate (right), half resolution, inliers in green, a label
// with ids, probability and inliers; the query alone with "no candidate" when there is none or its
// image is not cached. `query_keypoints` / `candidate_keypoints` at full resolution.
cv::Mat drawDebugImage(const cv::Mat& query_image, const std::vector<cv::KeyPoint>& query_keypoints,
                       const cv::Mat& candidate_image, const std::vector<cv::KeyPoint>& candidate_keypoints,
                       const mild::DetectionResult& result);

}  // namespace mild_lcd
