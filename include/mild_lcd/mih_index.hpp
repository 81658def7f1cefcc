#pragma once

#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include "mild_lcd/descriptor.hpp"
#include "mild_lcd/substring_layout.hpp"
#include "mild_lcd/types.hpp"

namespace mild {

struct MihParams {
  // m: number of hash tables, one per substring (seed paper: 16 for loop closure, 24 for sparse match).
  int num_tables = 16;
  // r: every bucket within Hamming distance r of the query's substring is probed (0..3).
  int radius = 0;
  // Bucket caps (seed paper III.D): a bucket holding more than
  //   max(min_bucket_cap, bucket_cap_factor * N_features / 2^substring_bits)
  // entries is discarded: emptied, ignored at query time and never grown again. N_features is
  // max(expected_features, features currently stored), so the cap never shrinks.
  bool cap_buckets = true;
  double bucket_cap_factor = 50.0;
  uint64_t expected_features = 1000000;
  uint32_t min_bucket_cap = 64;

  // Throws InvalidInput naming the first invalid field.
  void validate() const;
};

// Work done by one probe pass, summed over query features.
struct ProbeCounters {
  uint64_t buckets_probed = 0;
  uint64_t entries_visited = 0;
};

// Multi-index hash tables over feature ids. The index stores ids only; descriptors live with the
// caller (KeyframeDatabase, SparseMatcher), which is what lets a candidate be rejected on its first
// 64 bits without touching the rest.
class MihIndex {
 public:
  explicit MihIndex(const MihParams& params);

  const MihParams& params() const { return params_; }
  const SubstringLayout& layout() const { return layout_; }

  // Adds the features first_id .. first_id+count-1 of one keyframe. Ids must grow from call to call.
  // Intra-image burstiness: a bucket keeps at most one entry per keyframe, so a feature whose bucket
  // already holds an entry of this keyframe is not added to that table (it can still be found
  // through the other tables).
  void insertKeyframe(const Descriptor* descriptors, size_t count, FeatureId first_id);

  // Calls visit(feature_id, table) for every stored id below id_limit in every live bucket within
  // radius r of q's substrings. Within a bucket ids come in insertion order.
  template <class Visit>
  void probe(const Descriptor& q, FeatureId id_limit, ProbeCounters& counters, Visit&& visit) const;

  // True when substring t of a and b are within the probe radius, i.e. the pair meets in table t.
  bool meetsInTable(const Descriptor& a, const Descriptor& b, int t) const;

  size_t entryCount() const { return entry_count_; }
  size_t discardedBuckets() const { return discarded_buckets_; }
  size_t memoryBytes() const;
  void clear();

 private:
  struct Bucket {
    std::vector<FeatureId> ids;
    bool discarded = false;
  };
  struct Table {
    bool dense = true;
    std::vector<Bucket> dense_buckets;
    std::unordered_map<uint64_t, Bucket> sparse_buckets;

    const Bucket* find(uint64_t key) const;
    Bucket& at(uint64_t key);
  };

  size_t bucketCap(int t) const;

  MihParams params_;
  SubstringLayout layout_;
  std::vector<Table> tables_;
  // XOR masks with popcount <= r, per substring length (index = length).
  std::vector<std::vector<uint64_t>> probe_masks_;
  size_t entry_count_ = 0;
  size_t discarded_buckets_ = 0;
  uint64_t features_seen_ = 0;
};

template <class Visit>
void MihIndex::probe(const Descriptor& q, FeatureId id_limit, ProbeCounters& counters, Visit&& visit) const {
  const int m = layout_.count();
  for (int t = 0; t < m; ++t) {
    const uint64_t key = layout_.key(q, t);
    const Table& table = tables_[t];
    for (uint64_t flip : probe_masks_[layout_.length(t)]) {
      const Bucket* bucket = table.find(key ^ flip);
      ++counters.buckets_probed;
      if (bucket == nullptr || bucket->discarded) continue;
      for (FeatureId id : bucket->ids) {
        if (id >= id_limit) break;  // ids ascend within a bucket
        ++counters.entries_visited;
        visit(id, t);
      }
    }
  }
}

}  // namespace mild
