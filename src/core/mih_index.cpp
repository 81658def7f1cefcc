#include "mild_lcd/mih_index.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/errors.hpp"

namespace mild {
namespace {

constexpr int kMaxRadius = 3;
// Substrings up to this many bits get a directly addressed table (2^20 buckets at most);
// longer ones a hash map.
constexpr int kMaxDenseBits = 20;

void addMasks(int length, int radius, int first_bit, uint64_t mask, std::vector<uint64_t>& out) {
  out.push_back(mask);
  if (radius == 0) return;
  for (int b = first_bit; b < length; ++b) addMasks(length, radius - 1, b + 1, mask | (uint64_t{1} << b), out);
}

}  // namespace

void MihParams::validate() const {
  if (num_tables < SubstringLayout::kMinSubstrings || num_tables > SubstringLayout::kMaxSubstrings) {
    throw InvalidInput("index/num_tables must be in [" + std::to_string(SubstringLayout::kMinSubstrings) + ", " +
                       std::to_string(SubstringLayout::kMaxSubstrings) + "], got " + std::to_string(num_tables));
  }
  if (radius < 0 || radius > kMaxRadius) {
    throw InvalidInput("index/radius must be in [0, " + std::to_string(kMaxRadius) + "], got " + std::to_string(radius));
  }
  if (!(bucket_cap_factor > 0.0) || !std::isfinite(bucket_cap_factor)) {
    throw InvalidInput("index/bucket_cap_factor must be a positive number, got " + std::to_string(bucket_cap_factor));
  }
  if (min_bucket_cap < 1) throw InvalidInput("index/min_bucket_cap must be at least 1");
}

uint32_t MihIndex::Table::find(uint64_t key) const {
  if (dense) return static_cast<uint32_t>(key);
  auto it = slot_of.find(key);
  return it == slot_of.end() ? kNone : it->second;
}

uint32_t MihIndex::Table::findOrAdd(uint64_t key) {
  if (dense) return static_cast<uint32_t>(key);
  auto [it, added] = slot_of.emplace(key, static_cast<uint32_t>(count.size()));
  if (added) {  // a new, empty bucket before the end sentinel
    slots.insert(slots.end() - 1, Slot{slots.back().offset, kNone});
    count.push_back(0);
  }
  return it->second;
}

MihIndex::MihIndex(const MihParams& params) : params_(params), layout_((params.validate(), params.num_tables)) {
  probe_masks_.resize(layout_.maxLength() + 1);
  for (int t = 0; t < layout_.count(); ++t) {
    const int len = layout_.length(t);
    if (probe_masks_[len].empty()) addMasks(len, std::min(params_.radius, len), 0, 0, probe_masks_[len]);
  }
  clear();
}

void MihIndex::clear() {
  tables_.assign(layout_.count(), Table{});
  for (int t = 0; t < layout_.count(); ++t) {
    Table& table = tables_[t];
    table.dense = layout_.length(t) <= kMaxDenseBits;
    const size_t slots = table.dense ? size_t{1} << layout_.length(t) : 0;
    table.slots.assign(slots + 1, Slot{0, kNone});
    table.count.assign(slots, 0);
  }
  entry_count_ = 0;
  discarded_buckets_ = 0;
  features_seen_ = 0;
}

size_t MihIndex::bucketCap(int t) const {
  const double n_features = static_cast<double>(std::max<uint64_t>(params_.expected_features, features_seen_));
  const double average = n_features / std::ldexp(1.0, layout_.length(t));
  return std::max<size_t>(params_.min_bucket_cap, static_cast<size_t>(params_.bucket_cap_factor * average));
}

void MihIndex::insertKeyframe(const Descriptor* descriptors, size_t count, FeatureId first_id) {
  features_seen_ += count;
  for (int t = 0; t < layout_.count(); ++t) {
    Table& table = tables_[t];
    const size_t cap = bucketCap(t);
    for (size_t i = 0; i < count; ++i) {
      const uint32_t slot = table.findOrAdd(layout_.key(descriptors[i], t));
      uint32_t& head = table.slots[slot].recent;
      if (head == kDiscarded) continue;
      if (head != kNone && table.recent[head].id >= first_id) continue;  // this keyframe is already here
      uint32_t& entries = table.count[slot];
      if (params_.cap_buckets && entries >= cap) {
        // Discarded: ignored from now on; its entries leave memory at the next merge.
        entry_count_ -= entries;
        table.entries -= entries;
        entries = 0;
        head = kDiscarded;
        ++discarded_buckets_;
        continue;
      }
      table.recent.push_back({first_id + static_cast<FeatureId>(i), head});
      head = static_cast<uint32_t>(table.recent.size() - 1);
      ++entries;
      ++table.entries;
      ++entry_count_;
    }
    if (!merges_deferred_ && table.recent.size() > std::max<size_t>(4096, table.ids.size() / 64)) merge(table);
  }
}

void MihIndex::deferMerges(bool defer) {
  merges_deferred_ = defer;
  if (!defer) {
    for (Table& table : tables_) {
      if (!table.recent.empty()) merge(table);
    }
  }
}

void MihIndex::merge(Table& table) {
  const size_t slots = table.count.size();
  std::vector<FeatureId> ids;
  ids.reserve(table.entries);
  std::vector<FeatureId> chain;
  for (size_t s = 0; s < slots; ++s) {
    Slot& slot = table.slots[s];
    const uint32_t begin = slot.offset, end = table.slots[s + 1].offset;
    slot.offset = static_cast<uint32_t>(ids.size());
    if (slot.recent == kDiscarded) continue;
    ids.insert(ids.end(), table.ids.begin() + begin, table.ids.begin() + end);
    chain.clear();
    for (uint32_t link = slot.recent; link != kNone; link = table.recent[link].next) chain.push_back(table.recent[link].id);
    ids.insert(ids.end(), chain.rbegin(), chain.rend());  // oldest first: ids keep ascending
    slot.recent = kNone;
  }
  table.slots[slots].offset = static_cast<uint32_t>(ids.size());
  table.ids = std::move(ids);
  table.recent.clear();
}

bool MihIndex::meetsInTable(const Descriptor& a, const Descriptor& b, int t) const {
  return popcount64(layout_.key(a, t) ^ layout_.key(b, t)) <= params_.radius;
}

size_t MihIndex::memoryBytes() const {
  size_t bytes = sizeof(*this);
  for (const Table& table : tables_) {
    bytes += sizeof(Table) + table.slots.capacity() * sizeof(Slot) + table.ids.capacity() * sizeof(FeatureId) +
             table.count.capacity() * sizeof(uint32_t) + table.recent.capacity() * sizeof(Link);
    // unordered_map nodes: key, value, next pointer and cached hash, plus one bucket pointer each
    bytes += table.slot_of.size() * (sizeof(uint64_t) + sizeof(uint32_t) + 2 * sizeof(void*)) +
             table.slot_of.bucket_count() * sizeof(void*);
  }
  return bytes;
}

}  // namespace mild
