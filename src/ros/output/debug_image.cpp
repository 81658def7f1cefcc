#include "mild_lcd/ros/output/debug_image.hpp"

#include <algorithm>
#include <string>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace mild_lcd {

void DebugImageCache::remember(uint64_t id, const cv::Mat& image, mild::PixelFormat format, uint32_t robot) {
  const Key key(robot, id);
  if (max_images_ == 0 || max_bytes_ == 0 || image.empty()) return;
  cv::Mat small;
  const cv::Mat gray = mild::toGray(image, format);
  // An image of one or two pixels has no half; keep it as it is.
  if (gray.cols >= 2 && gray.rows >= 2) {
    cv::resize(gray, small, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
  } else {
    small = gray.clone();
  }
  const size_t size = small.total() * small.elemSize();
  if (size > max_bytes_) return;
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = images_.find(key);
  if (it != images_.end()) {
    bytes_ -= it->second.total() * it->second.elemSize();
    it->second = small;
  } else {
    images_.emplace(key, small);
    order_.push_back(key);
  }
  bytes_ += size;
  evict();
}

void DebugImageCache::evict() {
  while (!order_.empty() && (images_.size() > max_images_ || bytes_ > max_bytes_)) {
    auto it = images_.find(order_.front());
    if (it != images_.end()) {
      bytes_ -= it->second.total() * it->second.elemSize();
      images_.erase(it);
    }
    order_.pop_front();
  }
}

cv::Mat DebugImageCache::find(uint64_t id, uint32_t robot) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = images_.find(Key(robot, id));
  return it == images_.end() ? cv::Mat() : it->second;
}

void DebugImageCache::clear() {
  std::lock_guard<std::mutex> lock(mutex_);
  images_.clear();
  order_.clear();
  bytes_ = 0;
}

void DebugImageCache::clear(uint32_t robot) {
  std::lock_guard<std::mutex> lock(mutex_);
  for (auto it = images_.begin(); it != images_.end();) {
    if (it->first.first == robot) {
      bytes_ -= it->second.total() * it->second.elemSize();
      it = images_.erase(it);
    } else {
      ++it;
    }
  }
  order_.erase(std::remove_if(order_.begin(), order_.end(), [&](const Key& k) { return k.first == robot; }),
               order_.end());
}

size_t DebugImageCache::bytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return bytes_;
}

size_t DebugImageCache::size() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return images_.size();
}

namespace {

std::vector<cv::KeyPoint> halved(std::vector<cv::KeyPoint> keypoints) {
  for (auto& k : keypoints) k.pt *= 0.5f;
  return keypoints;
}

}  // namespace

cv::Mat drawDebugImage(const cv::Mat& query_image, const std::vector<cv::KeyPoint>& query_keypoints,
                       const cv::Mat& candidate_image, const std::vector<cv::KeyPoint>& candidate_keypoints,
                       const mild::DetectionResult& result) {
  cv::Mat canvas;
  if (result.candidates.empty() || candidate_image.empty()) {
    cv::cvtColor(query_image, canvas, cv::COLOR_GRAY2BGR);
    cv::putText(canvas, "no candidate", cv::Point(5, 15), cv::FONT_HERSHEY_PLAIN, 1.0, cv::Scalar(0, 0, 255));
    return canvas;
  }
  const mild::LoopCandidate& best = result.candidates.front();
  std::vector<cv::DMatch> inliers;
  for (const mild::FeatureMatch& m : best.verification.inlier_matches) {
    if (m.query < static_cast<int>(query_keypoints.size()) && m.train < static_cast<int>(candidate_keypoints.size())) {
      inliers.emplace_back(m.query, m.train, static_cast<float>(m.distance));
    }
  }
  cv::drawMatches(query_image, halved(query_keypoints), candidate_image, halved(candidate_keypoints), inliers, canvas,
                  cv::Scalar(0, 255, 0), cv::Scalar(120, 120, 120));
  const std::string label = "id " + std::to_string(result.query_id) + " -> " + std::to_string(best.id) +
                            "  p=" + std::to_string(best.probability).substr(0, 5) + "  inliers " +
                            std::to_string(best.verification.inliers);
  cv::putText(canvas, label, cv::Point(5, 15), cv::FONT_HERSHEY_PLAIN, 1.0,
              best.verification.verified ? cv::Scalar(0, 200, 0) : cv::Scalar(0, 0, 255));
  return canvas;
}

}  // namespace mild_lcd
