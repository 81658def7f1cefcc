#pragma once

// The original MILD (2017) index design, reproduced as the baseline of mild_bench_scale: 16 hash
// tables of per-bucket vectors holding (keyframe, feature) pairs, descriptors kept per keyframe,
// every candidate's full 256-bit distance computed, and a dense per-keyframe score vector cleared
// and summed for every query feature. Same similarity formula (phi, d0, IDF, vote mass) and the same
// bucket caps as mild_lcd, so that the two differ in data structures only.

#include <cstdint>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"
#include "mild_lcd/place/keyframe_database.hpp"

namespace mild::tools {

class Mild2017Index {
 public:
  explicit Mild2017Index(const DatabaseParams& params);

  void insert(const DescriptorList& descriptors);
  // Similarity of the query to every stored keyframe.
  std::vector<double> query(const DescriptorList& query) const;

  size_t size() const { return keyframes_.size(); }
  size_t memoryBytes() const;

 private:
  struct Entry {
    uint32_t keyframe;
    uint32_t feature;
  };
  static constexpr int kTables = 16;
  static constexpr int kBucketsPerTable = 1 << 16;

  DatabaseParams params_;
  PhiTable phi_;
  std::vector<std::vector<Entry>> buckets_;  // kTables * kBucketsPerTable
  std::vector<bool> discarded_;
  std::vector<DescriptorList> keyframes_;
  uint64_t features_ = 0;
};

}  // namespace mild::tools
