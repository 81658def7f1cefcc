#include "bench/mild2017_index.hpp"

#include <algorithm>
#include <cmath>

namespace mild::tools {
namespace {

uint32_t substring16(const Descriptor& d, int t) {
  return static_cast<uint32_t>((d.words[t / 4] >> (16 * (t % 4))) & 0xFFFF);
}

}  // namespace

Mild2017Index::Mild2017Index(const DatabaseParams& params)
    : params_(params),
      phi_(params.similarity),
      buckets_(kTables * kBucketsPerTable),
      discarded_(buckets_.size(), false) {}

void Mild2017Index::insert(const DescriptorList& descriptors) {
  const uint32_t k = static_cast<uint32_t>(keyframes_.size());
  features_ += descriptors.size();
  const double n = static_cast<double>(std::max<uint64_t>(params_.index.expected_features, features_));
  const size_t cap = std::max<size_t>(params_.index.min_bucket_cap,
                                      static_cast<size_t>(params_.index.bucket_cap_factor * n / kBucketsPerTable));
  for (uint32_t i = 0; i < descriptors.size(); ++i) {
    for (int t = 0; t < kTables; ++t) {
      const size_t b = static_cast<size_t>(t) * kBucketsPerTable + substring16(descriptors[i], t);
      std::vector<Entry>& bucket = buckets_[b];
      if (discarded_[b] || (!bucket.empty() && bucket.back().keyframe == k)) continue;
      if (params_.index.cap_buckets && bucket.size() >= cap) {
        std::vector<Entry>().swap(bucket);
        discarded_[b] = true;
        continue;
      }
      bucket.push_back({k, i});
    }
  }
  keyframes_.push_back(descriptors);
}

std::vector<double> Mild2017Index::query(const DescriptorList& query) const {
  const size_t n = keyframes_.size();
  const SimilarityParams& sp = params_.similarity;
  std::vector<double> score(n, 0.0);
  std::vector<double> feature_score(n);
  for (const Descriptor& f : query) {
    std::fill(feature_score.begin(), feature_score.end(), 0.0);
    for (int t = 0; t < kTables; ++t) {
      const size_t b = static_cast<size_t>(t) * kBucketsPerTable + substring16(f, t);
      for (const Entry& e : buckets_[b]) {
        const int d = hammingDistance(f, keyframes_[e.keyframe][e.feature]);
        if (d <= sp.max_distance) feature_score[e.keyframe] += phi_(d);
      }
    }
    double mass = sp.burstiness_regularizer;
    size_t hit = 0;
    for (double s : feature_score) {
      mass += s;
      hit += s > 0.0 ? 1 : 0;
    }
    if (hit == 0 || !(mass > 0.0)) continue;
    const double weight = (sp.idf_weighting ? std::log(static_cast<double>(n) / hit) : 1.0) / mass;
    for (size_t k = 0; k < n; ++k) score[k] += weight * feature_score[k];
  }
  return score;
}

size_t Mild2017Index::memoryBytes() const {
  size_t bytes = buckets_.capacity() * sizeof(std::vector<Entry>) + discarded_.capacity() / 8;
  for (const auto& b : buckets_) bytes += b.capacity() * sizeof(Entry);
  for (const auto& k : keyframes_) bytes += sizeof(DescriptorList) + k.capacity() * sizeof(Descriptor);
  return bytes;
}

}  // namespace mild::tools
