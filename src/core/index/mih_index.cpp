#include "mild_lcd/index/mih_index.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

// Substrings up to this many bits get a directly addressed table (2^20 buckets at most);
// longer ones a hash map.
constexpr int kMaxDenseBits = 20;

// A table's buckets are split into 2^kShardBits shards (64: a merge moves 1/64 of a table), directly
// addressed ones only while a shard keeps at least 2^kMinShardSlotBits of them, so that a merge's
// passes over its slots stay small against its entries. 16 shards of a 10,000-keyframe map still
// took 3 ms to merge one; 256 made inserts and queries slower (4,096 shard headers, 600 KB, no longer
// stay in cache, and every probed bucket reads one).
constexpr int kShardBits = 6;
constexpr int kMinShardSlotBits = 10;

// What an insertion spends on queued merges beyond the first shard, in entries moved plus eight per
// bucket slot (a merge's passes over them): up to about a millisecond here. Shards that do not fit
// wait, their new entries in chains, for the next insertions.
constexpr size_t kMergeBudget = size_t{1} << 17;
// Past this many waiting shards an insertion merges beyond its budget: on a small map many small
// shards come due at once, and a longer queue left their chains long enough to make queries on the
// 300-keyframe sample 50 % slower.
constexpr size_t kMaxWaitingShards = 64;

}  // namespace

size_t MihIndex::mergeThreshold(const Shard& shard) {
  // Recent entries cost a dependent load each at query time; 1/64 of the settled ones keeps them
  // rare. A merge moves every run, so without the room after each run (roomAfter) each entry was
  // copied about 64 times over its life; most new entries now land in that room instead. Measured on
  // the public sequences: a floor of 2,048 or 16,384 instead of 4,096 is slower (more merges, or
  // more chains); that floor is per table, shared by its shards. The shards grow alike, so with one
  // threshold all of them came due in the same keyframe: shard i of table t waits for (16 + (t + i) % 16) / 16 of it,
  // and their merges drift apart.
  return std::max<size_t>(shard.merge_floor, shard.ids.size() / 64) * (16 + shard.stagger) / 16;
}

uint32_t MihIndex::Shard::find(bool dense, uint64_t key) const {
  if (dense) return static_cast<uint32_t>(key);
  auto it = slot_of.find(key);
  return it == slot_of.end() ? kNone : it->second;
}

uint32_t MihIndex::Shard::findOrAdd(bool dense, uint64_t key) {
  if (dense) return static_cast<uint32_t>(key);
  auto [it, added] = slot_of.emplace(key, static_cast<uint32_t>(slots.size() - 1));
  if (added) {  // before the end sentinel, an empty run
    slots.insert(slots.end() - 1, Slot{slots.back().offset, slots.back().offset, kNone, 0});
  }
  return it->second;
}

MihIndex::MihIndex(const MihParams& params, int bits)
    : params_(params), layout_((params.validate(), params.tablesFor(bits)), bits) {
  probe_masks_ = layout_.probeMasks(params_.radius);
  // Per 16 tables, so that a table's share stays the same for wider descriptors (more tables).
  const uint64_t budget = (uint64_t{params_.max_candidates_per_feature} * layout_.count() + 15) / 16;
  query_budget_ = static_cast<uint32_t>(std::min<uint64_t>(budget, UINT32_MAX));
  clear();
}

void MihIndex::clear() {
  tables_.clear();  // destroyed, not assigned over: their arrays' memory goes back to the system
  tables_.resize(layout_.count());
  for (int t = 0; t < layout_.count(); ++t) {
    Table& table = tables_[t];
    const int length = layout_.length(t);
    table.dense = length <= kMaxDenseBits;
    table.shard_bits = table.dense ? std::clamp(length - kMinShardSlotBits, 0, kShardBits) : kShardBits;
    table.slot_bits = table.dense ? length - table.shard_bits : 0;
    table.shards.resize(size_t{1} << table.shard_bits);
    const size_t slots = table.dense ? size_t{1} << table.slot_bits : 0;
    for (size_t i = 0; i < table.shards.size(); ++i) {
      Shard& shard = table.shards[i];
      shard.merge_floor = static_cast<uint32_t>(4096 >> table.shard_bits);
      shard.stagger = static_cast<uint32_t>((t + i) % 16);
      shard.slots.assign(slots + 1, Slot{0, 0, kNone, 0});
    }
  }
  merge_queue_.clear();
  entry_count_ = 0;
  discarded_buckets_ = 0;
  evicted_entries_ = 0;
  features_seen_ = 0;
}

size_t MihIndex::bucketCap(int t) const {
  const double n_features = static_cast<double>(std::max<uint64_t>(params_.expected_features, features_seen_));
  const double average = n_features / std::ldexp(1.0, layout_.length(t));
  // A factor large enough to mean "no cap" must not wrap to a tiny one (a double beyond size_t's
  // range has no defined conversion).
  const double cap = std::min(params_.bucket_cap_factor * average, 0x1p62);
  return std::max<size_t>(params_.min_bucket_cap, static_cast<size_t>(cap));
}

void MihIndex::insertKeyframe(const Descriptor* descriptors, size_t count, FeatureId first_id) {
  features_seen_ += count;
  for (int t = 0; t < layout_.count(); ++t) {
    Table& table = tables_[t];
    const size_t cap = bucketCap(t);
    seen_.clear(count);
    keys_.resize(count);
    for (size_t i = 0; i < count; ++i) keys_[i] = layout_.key(descriptors[i], t);
    constexpr size_t kAhead = 8;  // buckets are scattered: request them a few features ahead
    for (size_t i = 0; i < count; ++i) {
      if (table.dense && i + kAhead < count) {
        const uint64_t ahead = keys_[i + kAhead];
        __builtin_prefetch(&table.shards[table.shardOf(ahead)].slots[table.keyInShard(ahead)]);
      }
      const uint64_t key = keys_[i];
      // Intra-image burstiness: the keyframe's first feature in a bucket is its only entry there.
      if (!seen_.insert(key)) continue;
      Shard& shard = table.shards[table.shardOf(key)];
      const uint32_t s = shard.findOrAdd(table.dense, table.keyInShard(key));
      Slot& slot = shard.slots[s];
      if (slot.recent == kDiscarded) continue;
      if (params_.cap_buckets && slot.count >= cap) {
        // Discarded: ignored from now on; its entries leave memory at the next merge.
        entry_count_ -= slot.count;
        slot.count = 0;
        slot.recent = kDiscarded;
        ++discarded_buckets_;
        continue;
      }
      const bool evict =
          params_.max_bucket_entries > 0 && slot.count >= params_.max_bucket_entries && slot.offset < slot.end;
      if (evict) {
        ++slot.offset;  // the oldest settled entry gives way (the merge drops recent ones over the bound)
        ++evicted_entries_;
      }
      const FeatureId id = first_id + static_cast<FeatureId>(i);
      if (slot.recent == kNone && slot.end < shard.slots[s + 1].offset) {
        // Room the last merge left after the run: the entry joins it, and is read with it.
        if (params_.inline_prefixes) shard.prefixes[slot.end] = descriptors[i].words[0];
        shard.ids[slot.end++] = id;
      } else {
        shard.recent.push_back({id, slot.recent, s, descriptors[i].words[0]});
        slot.recent = static_cast<uint32_t>(shard.recent.size() - 1);
      }
      if (evict) continue;
      ++slot.count;
      ++entry_count_;
    }
    // Bulk loading merges rarely (each entry is copied a few times instead of ~64), live insertion
    // often (recent entries are slower to probe).
    for (size_t i = 0; i < table.shards.size(); ++i) {
      Shard& shard = table.shards[i];
      const size_t threshold = merges_deferred_
                                   ? std::max<size_t>(size_t{1} << (16 - table.shard_bits), shard.ids.size() / 4)
                                   : mergeThreshold(shard);
      if (!shard.queued && shard.recent.size() > threshold) {
        shard.queued = true;
        merge_queue_.push_back({static_cast<uint16_t>(t), static_cast<uint16_t>(i)});
      }
    }
  }
  mergeQueued();
}

void MihIndex::mergeQueued() {
  size_t moved = 0;
  while (!merge_queue_.empty()) {
    Shard& shard = tables_[merge_queue_.front().table].shards[merge_queue_.front().shard];
    const size_t cost = shard.ids.size() + shard.recent.size() + 8 * slotCount(shard);
    const bool backlog = merge_queue_.size() > kMaxWaitingShards;
    if (!merges_deferred_ && !backlog && moved > 0 && moved + cost > kMergeBudget) break;
    merge_queue_.pop_front();
    shard.queued = false;
    merge(shard);
    moved += cost;
  }
}

void MihIndex::deferMerges(bool defer) {
  merges_deferred_ = defer;
  if (!defer) {
    merge_queue_.clear();
    for (Table& table : tables_) {
      for (Shard& shard : table.shards) {
        shard.queued = false;
        if (!shard.recent.empty()) merge(shard);
      }
    }
  }
}

namespace {

// Moves every bucket's kept settled run from[s] (length kept[s]) to start[s] within `array`, in
// place. Runs keep their order, so runs moving left are moved first to last and runs moving right
// last to first: neither overwrites a run that has yet to move.
template <class T>
void shiftRuns(T* array, const uint32_t* from, const uint32_t* kept, const uint32_t* start, size_t slots) {
  for (size_t s = 0; s < slots; ++s) {
    if (kept[s] > 0 && start[s] < from[s]) std::memmove(array + start[s], array + from[s], kept[s] * sizeof(T));
  }
  for (size_t s = slots; s-- > 0;) {
    if (kept[s] > 0 && start[s] > from[s]) std::memmove(array + start[s], array + from[s], kept[s] * sizeof(T));
  }
}

}  // namespace

uint32_t MihIndex::roomAfter(uint32_t entries) {
  // An eighth: buckets grow roughly in proportion to their length, so most of them fill their room
  // together, after the table has grown by about an eighth; until then new entries need no chain,
  // and merges (which move every run) come about eight times less often than with no room. Plus one,
  // for the empty and short buckets of a small map (5-15 % faster on pub_corridor and pub_city than
  // without it, for 4 MB at 16 tables).
  return entries / 8 + 1;
}

// The merge's second half: each recent entry written after its bucket's settled ones that stay (the
// oldest skip_recent[s] of a bucket over the bound dropped), then every slot's run closed at `start`.
void MihIndex::placeRecent(Shard& shard, const uint32_t* start, uint32_t* skip_recent, uint32_t bound) {
  const size_t slots = slotCount(shard);
  const bool prefixes = params_.inline_prefixes;
  Slot* const slot_at = shard.slots.data();
  FeatureId* const ids = shard.ids.data();
  uint64_t* const prefix_at = prefixes ? shard.prefixes.data() : nullptr;
  for (const Link& link : shard.recent) {
    Slot& slot = slot_at[link.slot];
    if (slot.recent == kDiscarded) continue;
    if (bound > 0 && skip_recent[link.slot] > 0) {
      --skip_recent[link.slot];
      continue;
    }
    if (prefixes) prefix_at[slot.offset] = link.prefix;
    ids[slot.offset++] = link.id;
  }
  for (size_t s = 0; s < slots; ++s) {
    Slot& slot = slot_at[s];
    slot.end = slot.offset;  // the write cursor, past the bucket's entries
    slot.offset = start[s];
    if (slot.recent != kDiscarded) {
      slot.recent = kNone;
      slot.count = slot.end - slot.offset;
    }
  }
  slot_at[slots].offset = slot_at[slots].end = start[slots];
}

void MihIndex::merge(Shard& shard) {
  // A counting sort of the recent entries by bucket: they are in insertion order, i.e. ascending
  // ids, so scattering them in that order keeps every bucket's ids ascending. Every pass over the
  // buckets is sequential, through plain pointers (a merge visits all 1,024 buckets of a shard).
  const size_t slots = slotCount(shard);
  const uint32_t bound = params_.max_bucket_entries;
  MergeScratch& scratch = merge_scratch_;
  scratch.start.resize(slots + 1);
  scratch.recent_in.assign(slots, 0);
  scratch.from.resize(slots);  // every element is written below
  scratch.kept.resize(slots);
  scratch.skip_recent.assign(bound > 0 ? slots : 0, 0);
  uint32_t* const start = scratch.start.data();
  uint32_t* const recent_in = scratch.recent_in.data();
  uint32_t* const from = scratch.from.data();
  uint32_t* const kept = scratch.kept.data();
  uint32_t* const skip_recent = scratch.skip_recent.data();
  Slot* const slot_at = shard.slots.data();
  for (const Link& link : shard.recent) ++recent_in[link.slot];  // discarded buckets: ignored below
  // Each bucket's settled entries that stay: from[s] .. from[s] + kept[s] in the array. Over the
  // bound (max_bucket_entries) a bucket's oldest entries go, settled ones first. Its offset becomes
  // its write cursor for the recent entries.
  start[0] = 0;
  uint64_t evicted = 0;
  for (size_t s = 0; s < slots; ++s) {
    Slot& slot = slot_at[s];
    const bool discarded = slot.recent == kDiscarded;
    if (discarded) recent_in[s] = 0;
    uint32_t settled = discarded ? 0 : slot.end - slot.offset;
    from[s] = slot.offset;
    uint32_t skipped = 0;
    if (bound > 0 && settled + recent_in[s] > bound) {
      uint32_t excess = settled + recent_in[s] - bound;
      const uint32_t from_settled = std::min(excess, settled);
      from[s] += from_settled;
      settled -= from_settled;
      skipped = excess - from_settled;
      skip_recent[s] = skipped;
      evicted += excess;
    }
    kept[s] = settled;
    const uint32_t entries = settled + recent_in[s] - skipped;
    start[s + 1] = start[s] + entries + roomAfter(entries);
    slot.offset = start[s] + settled;
  }
  evicted_entries_ += evicted;
  entry_count_ -= evicted;
  const size_t total = start[slots];
  const bool prefixes = params_.inline_prefixes;
  // Past its capacity an array grows by a 64th more (its mapping is extended, not copied: growing is
  // cheap, and spare capacity is memory), and the runs move within it as below. Each array on its own: their capacities
  // are rounded to pages of different numbers of elements.
  if (total > shard.ids.capacity()) shard.ids.reserve(total + total / 64);
  if (prefixes && total > shard.prefixes.capacity()) shard.prefixes.reserve(total + total / 64);
  shiftRuns(shard.ids.data(), from, kept, start, slots);
  if (prefixes) shiftRuns(shard.prefixes.data(), from, kept, start, slots);
  shard.ids.resize(total);  // shrinks after discards or evictions; the room stays
  if (prefixes) shard.prefixes.resize(total);
  placeRecent(shard, start, skip_recent, bound);
  shard.recent.clear();
  if (shard.recent.capacity() > 2 * mergeThreshold(shard)) {  // after a bulk load: give the room back
    std::vector<Link>().swap(shard.recent);
  }
}

void MihIndex::locate(const Descriptor& q, ProbeCounters& counters, ProbePlan& plan) const {
  plan.buckets_.clear();
  forEachProbedBucket(q, counters, [&plan](const Shard& shard, uint32_t slot, int t) {
    plan.buckets_.push_back({0, slot, t, &shard});
  });
}

void MihIndex::prepare(ProbePlan& plan) const {
  uint64_t total = 0;
  for (ProbePlan::Bucket& b : plan.buckets_) {
    const Shard& shard = *static_cast<const Shard*>(b.shard);
    const Slot& s = shard.slots[b.slot];
    b.length = s.recent == kDiscarded ? 0 : s.count;
    total += b.length;
    if (b.length == 0) continue;
    if (s.recent != kNone) __builtin_prefetch(&shard.recent[s.recent]);  // the newest entries are read first
    if (s.end > s.offset) {
      __builtin_prefetch(shard.ids.data() + s.end - 1);  // read newest first, from the run's end
      if (params_.inline_prefixes) __builtin_prefetch(shard.prefixes.data() + s.end - 1);
    }
  }
  plan.total_ = total;
  if (total > query_budget_) {  // not everything fits: the shortest buckets first (readPlanned)
    std::sort(plan.buckets_.begin(), plan.buckets_.end(), [](const ProbePlan::Bucket& a, const ProbePlan::Bucket& b) {
      return a.length != b.length ? a.length < b.length : a.t < b.t;
    });
  }
}

size_t MihIndex::chainedEntries() const {
  size_t chained = 0;
  for (const Table& table : tables_) {
    for (const Shard& shard : table.shards) chained += shard.recent.size();
  }
  return chained;
}

bool MihIndex::meetsInTable(const Descriptor& a, const Descriptor& b, int t) const {
  return popcount64(layout_.key(a, t) ^ layout_.key(b, t)) <= params_.radius;
}

size_t MihIndex::memoryBytes() const {
  size_t bytes = sizeof(*this);
  const MergeScratch& m = merge_scratch_;
  bytes +=
      (m.start.capacity() + m.recent_in.capacity() + m.from.capacity() + m.kept.capacity() + m.skip_recent.capacity()) *
      sizeof(uint32_t);
  bytes += merge_queue_.size() * sizeof(ShardRef);
  for (const Table& table : tables_) {
    bytes += sizeof(Table);
    for (const Shard& shard : table.shards) {
      bytes += sizeof(Shard) + shard.slots.capacity() * sizeof(Slot) + shard.ids.capacity() * sizeof(FeatureId) +
               shard.prefixes.capacity() * sizeof(uint64_t) + shard.recent.capacity() * sizeof(Link);
      // unordered_map nodes: key, value, next pointer and cached hash, plus one bucket pointer each
      bytes += shard.slot_of.size() * (sizeof(uint64_t) + sizeof(uint32_t) + 2 * sizeof(void*)) +
               shard.slot_of.bucket_count() * sizeof(void*);
    }
  }
  return bytes;
}

}  // namespace mild
