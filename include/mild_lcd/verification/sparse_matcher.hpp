#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/features/descriptor.hpp"
#include "mild_lcd/features/feature_match.hpp"
#include "mild_lcd/index/substring_layout.hpp"

namespace mild {

// Sparse match (seed paper IV.B): frame-to-frame matching by multi-index hashing. The train
// descriptors are hashed into m tables, each query descriptor looks up its own buckets, and the
// nearest train descriptor among those candidates is its match.
struct SparseMatchParams {
  // m. The seed paper uses 24; on 1,200-feature bench pairs 22 is 1.4x faster (29x brute force,
  // 12x FLANN LSH) and still recovers 97.7% of the brute-force pairs closer than 50 bits (24: 99.2%).
  int num_tables = 22;
  int radius = 0;         // r, multi-probe radius (0..2)
  int max_distance = 64;  // matches farther than this (Hamming) are dropped
  // Lowe's ratio test: keep a match only if best < ratio * second best (0 = off).
  double ratio = 0.0;
  // Keep a match only if it is also the query's nearest neighbour seen from the train side.
  bool cross_check = false;
  // With keypoints given: candidates farther than this many pixels from the query keypoint are
  // ignored (0 = off). For tracking between nearby frames.
  double max_keypoint_distance = 0.0;

  void validate() const;  // throws InvalidInput naming the first invalid field
};

// Work done by the last match() call (for benchmarks and tests).
struct SparseMatchStats {
  uint64_t candidates = 0;  // distance computations
  uint64_t buckets_probed = 0;
};

// Reusable matcher: buffers live across calls, so that setting up a pair costs time proportional
// to its number of features, never a clearing of all m * 2^(256/m) buckets. Not thread-safe; use
// one per thread.
class SparseMatcher {
 public:
  explicit SparseMatcher(const SparseMatchParams& params = {});
  const SparseMatchParams& params() const { return params_; }

  // One match per query descriptor at most, by query index. Keypoints are needed only for
  // max_keypoint_distance; when given they must have one entry per descriptor (InvalidInput
  // otherwise).
  std::vector<FeatureMatch> match(const DescriptorList& query, const DescriptorList& train,
                                  const std::vector<cv::KeyPoint>* query_keypoints = nullptr,
                                  const std::vector<cv::KeyPoint>* train_keypoints = nullptr);
  // OpenCV layout (N x 32 CV_8U); throws InvalidInput for any other.
  std::vector<FeatureMatch> match(const cv::Mat& query, const cv::Mat& train);

  const SparseMatchStats& lastStats() const { return stats_; }

 private:
  struct Nearest {
    int best = -1, best_distance = kDescriptorBits + 1, second_distance = kDescriptorBits + 1;
  };
  // Nearest and second-nearest train descriptor of every query among its MIH candidates.
  void searchAll(const DescriptorList& query, const DescriptorList& train, const std::vector<cv::KeyPoint>* qk,
                 const std::vector<cv::KeyPoint>* tk, std::vector<Nearest>& out);

  SparseMatchParams params_;
  SubstringLayout layout_;
  std::vector<std::vector<uint64_t>> probe_masks_;  // per substring length
  // Tables are processed one at a time, so one bucket array serves all of them: the table being
  // searched stays in L1. A bucket is valid only when its stamp equals the current generation, so
  // nothing is ever cleared between tables or pairs.
  struct Bucket {
    uint32_t stamp = 0;
    int32_t head = -1;
  };
  std::vector<Bucket> buckets_;
  uint32_t generation_ = 0;
  std::vector<int32_t> next_;  // chain links of the current table, one per train descriptor
  std::vector<Nearest> forward_, backward_;
  SparseMatchStats stats_;
};

}  // namespace mild
