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

const MihIndex::Bucket* MihIndex::Table::find(uint64_t key) const {
  if (dense) return &dense_buckets[key];
  auto it = sparse_buckets.find(key);
  return it == sparse_buckets.end() ? nullptr : &it->second;
}

MihIndex::Bucket& MihIndex::Table::at(uint64_t key) { return dense ? dense_buckets[key] : sparse_buckets[key]; }

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
    if (table.dense) table.dense_buckets.resize(size_t{1} << layout_.length(t));
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
      Bucket& bucket = table.at(layout_.key(descriptors[i], t));
      if (bucket.discarded) continue;
      if (!bucket.ids.empty() && bucket.ids.back() >= first_id) continue;  // this keyframe is already here
      if (params_.cap_buckets && bucket.ids.size() >= cap) {
        entry_count_ -= bucket.ids.size();
        std::vector<FeatureId>().swap(bucket.ids);
        bucket.discarded = true;
        ++discarded_buckets_;
        continue;
      }
      bucket.ids.push_back(first_id + static_cast<FeatureId>(i));
      ++entry_count_;
    }
  }
}

bool MihIndex::meetsInTable(const Descriptor& a, const Descriptor& b, int t) const {
  return popcount64(layout_.key(a, t) ^ layout_.key(b, t)) <= params_.radius;
}

size_t MihIndex::memoryBytes() const {
  size_t bytes = sizeof(*this);
  for (const Table& table : tables_) {
    bytes += table.dense_buckets.capacity() * sizeof(Bucket);
    for (const Bucket& b : table.dense_buckets) bytes += b.ids.capacity() * sizeof(FeatureId);
    for (const auto& kv : table.sparse_buckets) {
      bytes += sizeof(kv) + 2 * sizeof(void*) + kv.second.ids.capacity() * sizeof(FeatureId);
    }
  }
  return bytes;
}

}  // namespace mild
