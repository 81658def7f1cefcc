#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/features/descriptor.hpp"
#include "mild_lcd/features/feature_match.hpp"
#include "mild_lcd/index/substring_layout.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

// Sparse match (seed paper IV.B): frame-to-frame matching by multi-index hashing. The train
// descriptors are hashed into m tables, each query descriptor looks up its own buckets, and the
// nearest train descriptor among those candidates is its match.
struct SparseMatchParams {
  int num_tables = 0;     // m
  int radius = 0;         // r
  int max_distance = 64;  // per 256 bits
  double ratio = 0.0;     // Lowe's ratio test: best < ratio * second best (0 = off)
  bool cross_check = false;
  // With keypoints given: candidates farther than this many pixels from the query keypoint are
  // ignored (0 = off). For tracking between nearby frames; not a detector parameter.
  double max_keypoint_distance = 0.0;

  static constexpr int kMaxRadius = 2;
  static constexpr int kAutoSubstringBits = 12;
  static constexpr int kMaxSubstringBits = 20;  // directly addressed bucket arrays only
  // Matching is part of verification: its parameters are verification/'s.
  static constexpr const char* kSection = "verification";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("num_tables", p.num_tables, Bounds::in(SubstringLayout::kMinSubstrings, SubstringLayout::kMaxSubstrings).orZero(),
      "Sparse match: m hash tables (count, 0 = substrings of 12 bits, else 4 to 64).");
    v("radius", p.radius, Bounds::in(0, kMaxRadius), "Sparse match: multi-probe radius r (bits, 0 to 2).");
    v("max_distance", p.max_distance, Bounds::in(0, 256),
      "Sparse match: matches farther than this are dropped (bits per 256, scaled for other widths; 0 to 256).");
    v("ratio", p.ratio, Bounds::probability().runtime(),
      "Lowe's ratio test: a match is kept only if best < ratio * second best (ratio, 0 to 1; 0 = off).");
    v("cross_check", p.cross_check, Bounds::any(), "Whether only mutual nearest neighbours are kept (true or false).");
  }
  int tablesFor(int bits) const {
    return num_tables > 0 ? num_tables : SubstringLayout::substringsFor(bits, kAutoSubstringBits);
  }

  void validate() const;  // throws InvalidInput naming the first invalid field
  // Also that num_tables cuts descriptors of `bits` bits into substrings of at most 20 bits.
  void validateFor(int bits) const;
};

// Work done by the last match() call (for benchmarks and tests).
struct SparseMatchStats {
  uint64_t candidates = 0;  // distance computations
  uint64_t buckets_probed = 0;
};

// Reusable matcher: buffers live across calls, so that setting up a pair costs time proportional
// to its number of features, never a clearing of all m * 2^(bits/m) buckets. Any supported
// descriptor width; both sides of a pair must have the same. Not thread-safe; use one per thread.
class SparseMatcher {
 public:
  explicit SparseMatcher(const SparseMatchParams& params = {});
  const SparseMatchParams& params() const { return params_; }

  // One match per query descriptor at most, by query index. Keypoints are needed only for
  // max_keypoint_distance; when given they must have one entry per descriptor. Throws InvalidInput
  // for that, for descriptors of two widths, or a width num_tables cannot cut (validateFor).
  std::vector<FeatureMatch> match(const DescriptorList& query, const DescriptorList& train,
                                  const std::vector<cv::KeyPoint>* query_keypoints = nullptr,
                                  const std::vector<cv::KeyPoint>* train_keypoints = nullptr);
  // OpenCV layout (N x W CV_8U, W the width in bytes); throws InvalidInput for any other.
  std::vector<FeatureMatch> match(const cv::Mat& query, const cv::Mat& train);

  const SparseMatchStats& lastStats() const { return stats_; }

 private:
  struct Nearest {
    int best = -1, best_distance = kMaxDescriptorBits + 1, second_distance = kMaxDescriptorBits + 1;
  };
  // The substring layout of the width at hand, rebuilt when the width changes.
  void prepareFor(int bits);
  // Nearest and second-nearest train descriptor of every query among its MIH candidates.
  void searchAll(const DescriptorList& query, const DescriptorList& train, const std::vector<cv::KeyPoint>* qk,
                 const std::vector<cv::KeyPoint>* tk, std::vector<Nearest>& out);

  SparseMatchParams params_;
  std::optional<SubstringLayout> layout_;
  int max_distance_ = 0;                            // params_.max_distance at the layout's width
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
