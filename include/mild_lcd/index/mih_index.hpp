#pragma once

#include <algorithm>
#include <cstdint>
#include <deque>
#include <memory>
#include <unordered_map>
#include <vector>

#include "mild_lcd/common/mapped_array.hpp"
#include "mild_lcd/common/stamped_set.hpp"
#include "mild_lcd/common/types.hpp"
#include "mild_lcd/features/descriptor.hpp"
#include "mild_lcd/index/substring_layout.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

struct MihParams {
  int num_tables = 0;  // m
  int radius = 0;      // r
  bool cap_buckets = true;
  double bucket_cap_factor = 50.0;
  uint64_t expected_features = 1000000;
  uint32_t min_bucket_cap = 64;
  uint32_t max_bucket_entries = 256;
  uint32_t max_candidates_per_feature = 512;
  bool inline_prefixes = false;

  static constexpr int kMaxRadius = 3;
  static constexpr const char* kSection = "index";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("num_tables", p.num_tables, Bounds::in(SubstringLayout::kMinSubstrings, SubstringLayout::kMaxSubstrings).orZero(),
      "m, the hash tables of the index, one per substring of the descriptor (count, 0 = one per 16 bits, else 4 to "
      "64).");
    v("radius", p.radius, Bounds::in(0, kMaxRadius),
      "r, the multi-probe radius: every bucket within this Hamming distance of the query's substring is probed "
      "(bits, 0 to 3).");
    v("cap_buckets", p.cap_buckets, Bounds::any(),
      "Whether a bucket of more than max(min_bucket_cap, bucket_cap_factor * N / 2^substring_bits) entries, N = "
      "max(expected_features, features stored), is discarded (true or false).");
    v("bucket_cap_factor", p.bucket_cap_factor, Bounds::above(0),
      "The bucket cap as a multiple of the average bucket length (factor, > 0).");
    v("expected_features", p.expected_features, Bounds::atLeast(0),
      "N of the bucket cap while the map holds fewer features (features, >= 0).");
    v("min_bucket_cap", p.min_bucket_cap, Bounds::atLeast(1), "Least bucket cap (entries, >= 1).");
    v("max_bucket_entries", p.max_bucket_entries, Bounds::atLeast(2).orZero(),
      "Entries a bucket keeps, its newest, so that query time stays bounded as the map grows (entries, 0 = "
      "unbounded, else >= 2).");
    v("max_candidates_per_feature", p.max_candidates_per_feature, Bounds::atLeast(1).orZero(),
      "Index entries a query feature reads per 16 tables, shortest buckets first (entries, scaled by m / 16; 0 = "
      "all, else >= 1).");
    v("inline_prefixes", p.inline_prefixes, Bounds::any(),
      "Whether index entries hold their feature's first 64 bits, so that early termination reads buckets "
      "sequentially for 8 bytes more per entry (true or false).");
  }
  static constexpr int kAutoSubstringBits = 16;
  // The table count for descriptors of `bits` bits: num_tables, or the automatic choice.
  int tablesFor(int bits) const {
    return num_tables > 0 ? num_tables : SubstringLayout::substringsFor(bits, kAutoSubstringBits);
  }
  void validate() const { validateDeclared(*this); }
};

// The ids a probe reads: those below `end`. With a query budget, ids at or above `unbudgeted_from`
// are read besides it, without counting against it, in the buckets the budget reaches: a caller
// that also wants the newest keyframes' matches for another purpose (the near-past band reads the
// exclusion window) then gets the same ids below `unbudgeted_from` as a probe that stops there, and
// the newest keyframes' matches from the same buckets as theirs. From a plain id: every id below
// it, all of them budgeted.
struct IdRange {
  IdRange(FeatureId id_end) : end(id_end), unbudgeted_from(id_end) {}  // NOLINT(google-explicit-constructor)
  IdRange(FeatureId id_end, FeatureId unbudgeted) : end(id_end), unbudgeted_from(std::min(unbudgeted, id_end)) {}
  FeatureId end;
  FeatureId unbudgeted_from;
};

// Work done by one probe pass, summed over query features.
struct ProbeCounters {
  uint64_t buckets_probed = 0;
  uint64_t entries_visited = 0;
};

// Multi-index hash tables over feature ids. The index stores ids only; descriptors live with the
// caller (KeyframeDatabase, SparseMatcher), which is what lets a candidate be rejected on its first
// 64 bits without touching the rest.
//
// Layout, per table. A table's buckets are split into shards (64 for 16-bit substrings: by their
// top 6 bits), each with arrays of its own. Buckets are slots: the substring's low bits for
// substrings up to 20 bits (every slot preallocated), or a slot number handed out on first use for
// longer substrings. Settled entries sit in one contiguous array per shard, bucket after bucket
// (compressed sparse rows), so a probe reads a bucket's ids in one sequential run. Each run is
// followed by free room (roomAfter: an eighth of its length plus one, left by the last merge), where
// new entries of that bucket go; once it is full they sit in per-bucket chains. When the chains of a
// shard hold more than 1/64 of its settled entries they are merged into its array: each entry is
// copied a bounded number of times over its life, and no bucket carries the 24-byte header of a
// vector of its own. A merge shifts the runs within the array (which grows by remapping, a 64th at
// a time), so that it neither allocates nor clears a new array of every entry. Shards due for a
// merge wait in a queue, and an insertion merges from it within a budget (at least one shard, and
// beyond the budget while more than 64 wait): no insertion moves a whole table (docs/speed.md, "Insert
// time", "Room after each run", "Bounded insert time").
class MihIndex {
 public:
  // An index over descriptors of `bits` bits. Throws InvalidInput when the parameters do not fit
  // that width (substrings longer than 64 bits).
  MihIndex(const MihParams& params, int bits);

  const MihParams& params() const { return params_; }
  const SubstringLayout& layout() const { return layout_; }

  // Adds the features first_id .. first_id+count-1 of one keyframe. Ids must grow from call to call.
  // Intra-image burstiness: a bucket keeps at most one entry per keyframe, so a feature whose bucket
  // already holds an entry of this keyframe is not added to that table (it can still be found
  // through the other tables).
  // Every descriptor must have the index's width (callers check).
  void insertKeyframe(const Descriptor* descriptors, size_t count, FeatureId first_id);

  // Bulk loading: while deferred, recent entries are merged into the contiguous runs rarely (each
  // entry is copied a few times, not ~64), and ending the deferral merges every table. Queries and
  // results are the same either way.
  void deferMerges(bool defer);

  // Calls visit(feature_id, table) for every stored id below id_limit in every live bucket within
  // radius r of q's substrings (in no particular order within a bucket); with a query budget
  // (max_candidates_per_feature), for the ids of the shortest buckets up to that many.
  template <class Visit>
  void probe(const Descriptor& q, IdRange ids, ProbeCounters& counters, Visit&& visit) const;

  // With inline_prefixes: calls visit(feature_id, first_64_bits) for the same entries, read from
  // the buckets themselves.
  template <class Visit>
  void probeWithPrefixes(const Descriptor& q, IdRange ids, ProbeCounters& counters, Visit&& visit) const;

  // The same ids appended to `out`, table after table, for callers that process them in bulk.
  void gather(const Descriptor& q, IdRange ids, ProbeCounters& counters, std::vector<FeatureId>& out) const {
    probe(q, ids, counters, [&out](FeatureId id, int) { out.push_back(id); });
  }

  // probe() with a query budget, in three steps, so that a caller with many query features can
  // overlap one feature's memory reads with another's work: locate() finds the feature's buckets and
  // requests their headers from memory, prepare() (a little later) reads their lengths and requests
  // their newest entries, gatherPlanned() (later still) appends the same ids as gather(), in the same
  // order. A bucket's header and its entries each cost a read from memory per table; requested one
  // feature at a time, the 16 tables' reads overlapped only each other (docs/speed.md, "Reads
  // requested ahead"). Only for an index with a query budget (hasQueryBudget()).
  class ProbePlan {
    friend class MihIndex;
    struct Bucket {
      uint32_t length;
      uint32_t slot;
      int t;
      const void* shard;
    };
    std::vector<Bucket> buckets_;
    uint64_t total_ = 0;
  };
  bool hasQueryBudget() const { return query_budget_ > 0; }
  void locate(const Descriptor& q, ProbeCounters& counters, ProbePlan& plan) const;
  void prepare(ProbePlan& plan) const;
  void gatherPlanned(const ProbePlan& plan, IdRange ids, ProbeCounters& counters, std::vector<FeatureId>& out) const {
    readPlanned<false>(plan, ids, counters, [&out](FeatureId id, uint64_t, int) { out.push_back(id); });
  }

  // True when substring t of a and b are within the probe radius, i.e. the pair meets in table t.
  bool meetsInTable(const Descriptor& a, const Descriptor& b, int t) const;

  size_t entryCount() const { return entry_count_; }
  // Entries waiting in chains for their shard's merge (each costs a dependent read at query time).
  size_t chainedEntries() const;
  size_t discardedBuckets() const { return discarded_buckets_; }
  uint64_t evictedEntries() const { return evicted_entries_; }
  size_t memoryBytes() const;
  void clear();

 private:
  static constexpr uint32_t kNone = 0xFFFFFFFFu;       // no slot, or the end of a chain
  static constexpr uint32_t kDiscarded = 0xFFFFFFFEu;  // in place of a chain: the bucket went over its cap

  struct Link {
    FeatureId id;
    uint32_t next;    // older link of the same bucket, or kNone
    uint32_t slot;    // its bucket, so that merging needs no walk along the chains
    uint64_t prefix;  // the feature's first 64 bits (inline_prefixes)
  };
  // A bucket, in one place: its settled run is [offset, end); `recent` is its newest recent link,
  // kNone, or kDiscarded; `count` its entries, settled and recent (for the cap). The run keeps an
  // end of its own, rather than ending where the next slot's starts, because with bounded buckets a
  // run's oldest entries give way by moving its start: the run before must not grow into them.
  struct Slot {
    uint32_t offset;
    uint32_t end;
    uint32_t recent;
    uint32_t count;
  };
  // One range of a table's buckets with arrays of its own, so that a merge moves one shard's
  // entries, not the table's (docs/speed.md, "Insert time").
  struct Shard {
    std::unordered_map<uint64_t, uint32_t> slot_of;  // substring value -> slot (long substrings)
    std::vector<Slot> slots;                         // one per bucket, plus an end sentinel
    // 4 KB pages: a shard's array is a few megabytes at most (bounded buckets), and rounding each of
    // 1,024 of them up to 2 MB pages costs memory (16 shards with huge pages: +17 bytes per feature at
    // 10,000 keyframes; docs/speed.md, "Insert time").
    MappedArray<FeatureId, false> ids;      // settled entries, bucket after bucket
    MappedArray<uint64_t, false> prefixes;  // beside ids (inline_prefixes), else empty
    std::vector<Link> recent;
    uint32_t merge_floor = 0;  // mergeThreshold's least number of recent entries
    uint32_t stagger = 0;      // spreads the shards' merges over different keyframes (mergeThreshold)
    bool queued = false;       // waits in merge_queue_

    uint32_t find(bool dense, uint64_t key) const;
    uint32_t findOrAdd(bool dense, uint64_t key);
  };
  struct Table {
    bool dense = true;
    int shard_bits = 0;  // 2^shard_bits shards
    int slot_bits = 0;   // dense: the low slot_bits of a substring are its slot in its shard
    std::vector<Shard> shards;

    // The shard holding a substring's bucket, and the substring as that shard knows it.
    size_t shardOf(uint64_t key) const {
      if (shard_bits == 0) return 0;
      return dense ? key >> slot_bits : (key * 0x9E3779B97F4A7C15ull) >> (64 - shard_bits);
    }
    uint64_t keyInShard(uint64_t key) const { return dense ? key & ((uint64_t{1} << slot_bits) - 1) : key; }
  };
  struct ShardRef {
    uint16_t table;
    uint16_t shard;
  };

  size_t bucketCap(int t) const;
  // Calls found(shard, slot, t) for every existing bucket within radius r of q's substrings, its
  // slot already requested from memory.
  template <class Found>
  void forEachProbedBucket(const Descriptor& q, ProbeCounters& counters, Found&& found) const;
  template <bool kPrefixes, class Visit>
  void probeRuns(const Descriptor& q, IdRange ids, ProbeCounters& counters, Visit&& visit) const;
  template <bool kPrefixes, class Visit>
  void probeWithinBudget(const Descriptor& q, IdRange ids, ProbeCounters& counters, Visit&& visit) const;
  template <bool kPrefixes, class Visit>
  void readPlanned(const ProbePlan& plan, IdRange ids, ProbeCounters& counters, Visit&& visit) const;
  void merge(Shard& shard);
  void placeRecent(Shard& shard, const uint32_t* start, uint32_t* skip_recent, uint32_t bound);
  // Merges the shards waiting in merge_queue_, oldest first, up to kMergeBudget entries moved (at
  // least one shard); all of them while merges are deferred.
  void mergeQueued();
  static uint32_t roomAfter(uint32_t entries);  // free entries a merge leaves after a run of `entries`
  static size_t slotCount(const Shard& shard) { return shard.slots.size() - 1; }
  static size_t mergeThreshold(const Shard& shard);

  MihParams params_;
  SubstringLayout layout_;
  std::vector<Table> tables_;
  std::deque<ShardRef> merge_queue_;  // shards whose chains passed their threshold, oldest first
  // XOR masks with popcount <= r, per substring length (index = length).
  std::vector<std::vector<uint64_t>> probe_masks_;
  uint32_t query_budget_ = 0;  // max_candidates_per_feature scaled to the table count
  size_t entry_count_ = 0;
  size_t discarded_buckets_ = 0;
  uint64_t evicted_entries_ = 0;
  uint64_t features_seen_ = 0;
  bool merges_deferred_ = false;
  // Substrings the keyframe being inserted already put into the table at hand.
  StampedSet seen_;
  std::vector<uint64_t> keys_;  // the keyframe's substrings for the table at hand
  // merge()'s per-bucket counts, kept between merges: allocated anew, five arrays of 65,536 counts
  // were faulted in (and zeroed) for every merge (docs/speed.md, "Insert time", measures the difference).
  struct MergeScratch {
    std::vector<uint32_t> start, recent_in, from, kept, skip_recent;
  };
  MergeScratch merge_scratch_;
};

template <class Visit>
void MihIndex::probe(const Descriptor& q, IdRange ids, ProbeCounters& counters, Visit&& visit) const {
  probeRuns<false>(q, ids, counters, [&](FeatureId id, uint64_t, int t) { visit(id, t); });
}

template <class Visit>
void MihIndex::probeWithPrefixes(const Descriptor& q, IdRange ids, ProbeCounters& counters, Visit&& visit) const {
  probeRuns<true>(q, ids, counters, [&](FeatureId id, uint64_t prefix, int) { visit(id, prefix); });
}

template <class Found>
void MihIndex::forEachProbedBucket(const Descriptor& q, ProbeCounters& counters, Found&& found) const {
  const int m = layout_.count();
  for (int t = 0; t < m; ++t) {
    const uint64_t key = layout_.key(q, t);
    const Table& table = tables_[t];
    for (uint64_t flip : probe_masks_[layout_.length(t)]) {
      ++counters.buckets_probed;
      const uint64_t probed = key ^ flip;
      const Shard& shard = table.shards[table.shardOf(probed)];
      const uint32_t slot = shard.find(table.dense, table.keyInShard(probed));
      if (slot == kNone) continue;
      __builtin_prefetch(&shard.slots[slot]);
      found(shard, slot, t);
    }
  }
}

template <bool kPrefixes, class Visit>
void MihIndex::probeRuns(const Descriptor& q, IdRange ids, ProbeCounters& counters, Visit&& visit) const {
  if (query_budget_ > 0) {
    probeWithinBudget<kPrefixes>(q, ids, counters, visit);
    return;
  }
  const FeatureId id_limit = ids.end;  // without a budget every id below the end is read
  // Buckets are scattered in memory. Their slots are requested in a batch first, then their runs,
  // so that the loads overlap instead of following one another.
  constexpr size_t kBatch = 64;
  struct Pending {
    const Shard* shard;
    uint32_t slot;
    int t;
  };
  Pending batch[kBatch];
  size_t pending = 0;
  const auto drain = [&] {
    for (size_t i = 0; i < pending; ++i) {
      const Slot& s = batch[i].shard->slots[batch[i].slot];
      __builtin_prefetch(batch[i].shard->ids.data() + s.offset);
      if constexpr (kPrefixes) __builtin_prefetch(batch[i].shard->prefixes.data() + s.offset);
    }
    for (size_t i = 0; i < pending; ++i) {
      const Shard& shard = *batch[i].shard;
      const Slot& s = shard.slots[batch[i].slot];
      if (s.recent == kDiscarded) continue;
      const uint32_t begin = s.offset, end = s.end;
      const FeatureId* ids = shard.ids.data();
      for (uint32_t e = begin; e != end && ids[e] < id_limit; ++e) {  // settled ids ascend within a bucket
        ++counters.entries_visited;
        if constexpr (kPrefixes) {
          visit(ids[e], shard.prefixes[e], batch[i].t);
        } else {
          visit(ids[e], uint64_t{0}, batch[i].t);
        }
      }
      for (uint32_t link = s.recent; link != kNone; link = shard.recent[link].next) {
        const Link& l = shard.recent[link];
        if (l.id >= id_limit) continue;  // recent ids descend: newest first
        ++counters.entries_visited;
        visit(l.id, l.prefix, batch[i].t);
      }
    }
    pending = 0;
  };
  forEachProbedBucket(q, counters, [&](const Shard& shard, uint32_t slot, int t) {
    batch[pending++] = {&shard, slot, t};
    if (pending == kBatch) drain();
  });
  drain();
}

template <bool kPrefixes, class Visit>
void MihIndex::probeWithinBudget(const Descriptor& q, IdRange ids, ProbeCounters& counters, Visit&& visit) const {
  thread_local ProbePlan plan;
  locate(q, counters, plan);
  prepare(plan);
  readPlanned<kPrefixes>(plan, ids, counters, visit);
}

template <bool kPrefixes, class Visit>
void MihIndex::readPlanned(const ProbePlan& plan, IdRange ids, ProbeCounters& counters, Visit&& visit) const {
  // The buckets of one query feature, shortest first when they do not all fit (prepare() sorted
  // them): a short bucket is a distinctive substring (high IDF, and what finds an old place); the
  // longest ones are what grows with the map. Within a bucket the newest ids come first, so the
  // unbudgeted ones (at or above ids.unbudgeted_from) are read before the budget is touched; and
  // only in the buckets the budget reaches, so that what is counted of them and of the budgeted ids
  // comes from the same buckets (the near-past band compares the two counts).
  const FeatureId id_limit = ids.end, free_from = ids.unbudgeted_from;
  uint32_t budget = query_budget_;
  const auto read = [&](FeatureId id, uint64_t prefix, int t) {
    ++counters.entries_visited;
    visit(id, prefix, t);
  };
  for (const ProbePlan::Bucket& b : plan.buckets_) {
    if (budget == 0) break;
    if (b.length == 0) continue;
    const Shard& shard = *static_cast<const Shard*>(b.shard);
    const Slot& s = shard.slots[b.slot];
    for (uint32_t link = s.recent; link != kNone; link = shard.recent[link].next) {
      const Link& l = shard.recent[link];
      if (l.id >= id_limit) continue;  // recent ids descend: newest first
      if (l.id >= free_from) {
        read(l.id, l.prefix, b.t);
        continue;
      }
      if (budget == 0) break;
      --budget;
      read(l.id, l.prefix, b.t);
    }
    const FeatureId* ids_of = shard.ids.data();
    uint32_t e = s.end;
    while (e != s.offset && ids_of[e - 1] >= id_limit) --e;  // settled ids ascend within a bucket
    for (; e != s.offset && ids_of[e - 1] >= free_from; --e) {
      read(ids_of[e - 1], kPrefixes ? shard.prefixes[e - 1] : uint64_t{0}, b.t);
    }
    for (; e != s.offset && budget > 0; --e, --budget) {
      read(ids_of[e - 1], kPrefixes ? shard.prefixes[e - 1] : uint64_t{0}, b.t);
    }
  }
}

}  // namespace mild
