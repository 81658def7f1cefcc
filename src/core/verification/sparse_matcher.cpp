#include "mild_lcd/verification/sparse_matcher.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/descriptor.hpp"

namespace mild {
void SparseMatchParams::validate() const {
  validateDeclared(*this);
  if (!(max_keypoint_distance >= 0.0) || !std::isfinite(max_keypoint_distance)) {
    throw InvalidInput("sparse match max_keypoint_distance must be >= 0 (0 = off)");
  }
}

void SparseMatchParams::validateFor(int bits) const {
  validate();
  const int tables = tablesFor(bits);
  const int fewest = SubstringLayout::substringsFor(bits, kMaxSubstringBits);
  if (tables < fewest) {
    throw InvalidInput("sparse match num_tables (verification/num_tables) must be 0 (automatic) or at least " +
                       std::to_string(fewest) + " for " + std::to_string(bits) +
                       "-bit descriptors (substrings of at most " + std::to_string(kMaxSubstringBits) + " bits), got " +
                       std::to_string(tables));
  }
}

SparseMatcher::SparseMatcher(const SparseMatchParams& params) : params_((params.validate(), params)) {}

void SparseMatcher::prepareFor(int bits) {
  if (layout_ && layout_->bits() == bits) return;
  params_.validateFor(bits);
  layout_.emplace(params_.tablesFor(bits), bits);
  max_distance_ = scaleDistance(params_.max_distance, bits);
  probe_masks_ = layout_->probeMasks(params_.radius);
  buckets_.assign(size_t{1} << layout_->maxLength(), Bucket{});
  generation_ = 0;
}

void SparseMatcher::searchAll(const DescriptorList& query, const DescriptorList& train,
                              const std::vector<cv::KeyPoint>* qk, const std::vector<cv::KeyPoint>* tk,
                              std::vector<Nearest>& out) {
  const size_t n = train.size();
  next_.resize(n);
  out.assign(query.size(), Nearest{});
  const bool gate = params_.max_keypoint_distance > 0.0 && qk != nullptr && tk != nullptr;
  const float gate2 = static_cast<float>(params_.max_keypoint_distance * params_.max_keypoint_distance);
  Bucket* buckets = buckets_.data();
  int32_t* next = next_.data();
  uint64_t candidates = 0;

  const SubstringLayout& layout = *layout_;
  for (int t = 0; t < layout.count(); ++t) {
    if (++generation_ == 0) {  // wrapped: an old stamp could look current, so clear once
      std::fill(buckets_.begin(), buckets_.end(), Bucket{});
      generation_ = 1;
    }
    // Hash the train descriptors; inserting in reverse keeps every chain in index order.
    for (size_t i = n; i-- > 0;) {
      Bucket& b = buckets[layout.key(train[i], t)];
      if (b.stamp != generation_) b = Bucket{generation_, -1};
      next[i] = b.head;
      b.head = static_cast<int32_t>(i);
    }
    const std::vector<uint64_t>& masks = probe_masks_[layout.length(t)];
    stats_.buckets_probed += query.size() * masks.size();
    for (size_t q = 0; q < query.size(); ++q) {
      const Descriptor& d = query[q];
      Nearest& near = out[q];
      const uint64_t key = layout.key(d, t);
      auto visit = [&](const Bucket& b) {
        if (b.stamp != generation_) return;
        for (int32_t i = b.head; i >= 0; i = next[i]) {
          // A pair that meets in several tables is seen several times; only the nearest and the
          // second-nearest distance matter, and a repeat of the nearest must not become second.
          if (i == near.best) continue;
          if (gate) {
            const float dx = (*qk)[q].pt.x - (*tk)[i].pt.x, dy = (*qk)[q].pt.y - (*tk)[i].pt.y;
            if (dx * dx + dy * dy > gate2) continue;
          }
          ++candidates;
          const int dist = hammingDistance(d, train[i]);
          if (dist < near.best_distance) {
            near.second_distance = near.best_distance;
            near.best_distance = dist;
            near.best = i;
          } else if (dist < near.second_distance) {
            near.second_distance = dist;
          }
        }
      };
      if (masks.size() == 1) {
        visit(buckets[key]);  // r = 0, the default: one bucket per table
      } else {
        for (uint64_t flip : masks) visit(buckets[key ^ flip]);
      }
    }
  }
  stats_.candidates += candidates;
}

std::vector<FeatureMatch> SparseMatcher::match(const cv::Mat& query, const cv::Mat& train) {
  return match(descriptorsFromMat(query), descriptorsFromMat(train, query.empty() ? 0 : query.cols));
}

std::vector<FeatureMatch> SparseMatcher::match(const DescriptorList& query, const DescriptorList& train,
                                               const std::vector<cv::KeyPoint>* query_keypoints,
                                               const std::vector<cv::KeyPoint>* train_keypoints) {
  if (query_keypoints && query_keypoints->size() != query.size()) {
    throw InvalidInput("query keypoints (" + std::to_string(query_keypoints->size()) + ") and descriptors (" +
                       std::to_string(query.size()) + ") differ in number");
  }
  if (train_keypoints && train_keypoints->size() != train.size()) {
    throw InvalidInput("train keypoints (" + std::to_string(train_keypoints->size()) + ") and descriptors (" +
                       std::to_string(train.size()) + ") differ in number");
  }
  if (query.size() > static_cast<size_t>(INT32_MAX) || train.size() > static_cast<size_t>(INT32_MAX)) {
    throw InvalidInput("too many descriptors to match");
  }
  stats_ = SparseMatchStats{};
  std::vector<FeatureMatch> matches;
  if (query.empty() || train.empty()) return matches;
  const int bytes = query.front().bytes;
  checkDescriptorWidth(query, bytes, "query");
  checkDescriptorWidth(train, bytes, "train set");
  prepareFor(bytes * 8);

  searchAll(query, train, query_keypoints, train_keypoints, forward_);
  if (params_.cross_check) searchAll(train, query, train_keypoints, query_keypoints, backward_);

  for (size_t q = 0; q < query.size(); ++q) {
    const Nearest& f = forward_[q];
    if (f.best < 0 || f.best_distance > max_distance_) continue;
    if (params_.ratio > 0.0 && !(f.best_distance < params_.ratio * f.second_distance)) continue;
    if (params_.cross_check && backward_[f.best].best != static_cast<int>(q)) continue;
    matches.push_back({static_cast<int>(q), f.best, f.best_distance});
  }
  return matches;
}

}  // namespace mild
