#include "bench/faiss_baselines.hpp"

#include <omp.h>

#include <faiss/IndexBinaryFlat.h>
#include <faiss/IndexBinaryHash.h>
#include <faiss/impl/AuxIndexStructures.h>

#include "mild_lcd/common/errors.hpp"

namespace mild::tools {
namespace {

// faiss codes are the descriptors' bytes back to back, as in an OpenCV matrix.
std::vector<uint8_t> codes(const DescriptorList& descriptors) {
  std::vector<uint8_t> out;
  appendDescriptorBytes(descriptors, out);
  return out;
}

}  // namespace

FaissBaselines::FaissBaselines(int bits, int tables) : bytes_(bits / 8) {
  if (tables < 1 || bits % tables != 0 || bits % 8 != 0) {
    throw InvalidInput("faiss baseline: the table count must divide " + std::to_string(bits));
  }
  omp_set_num_threads(1);  // the benchmark compares kernels on one thread
  index_ = std::make_unique<faiss::IndexBinaryMultiHash>(bits, tables, bits / tables);
  index_->nflip = 0;  // probe radius 0, as mild_lcd's default
}

FaissBaselines::~FaissBaselines() = default;

void FaissBaselines::add(const DescriptorList& keyframe) {
  if (!keyframe.empty()) index_->add(static_cast<faiss::IndexBinary::idx_t>(keyframe.size()), codes(keyframe).data());
}

size_t FaissBaselines::queryMultiHash(const DescriptorList& query, int max_distance) const {
  faiss::RangeSearchResult result(static_cast<faiss::IndexBinary::idx_t>(query.size()));
  index_->range_search(static_cast<faiss::IndexBinary::idx_t>(query.size()), codes(query).data(), max_distance + 1,
                       &result);
  return result.lims[query.size()];
}

size_t FaissBaselines::queryExact(const DescriptorList& query, int max_distance) const {
  faiss::RangeSearchResult result(static_cast<faiss::IndexBinary::idx_t>(query.size()));
  index_->storage->range_search(static_cast<faiss::IndexBinary::idx_t>(query.size()), codes(query).data(),
                                max_distance + 1, &result);
  return result.lims[query.size()];
}

double FaissBaselines::entryBytesPerFeature() const {
  if (index_->ntotal == 0) return 0.0;
  // Every feature is in every map (an 8-byte id); hashtable_size() counts the non-empty buckets, each
  // an unordered_map node holding its key and a std::vector header (about 56 bytes with libstdc++).
  const double ids = 8.0 * index_->nhash;
  const double buckets = 56.0 * static_cast<double>(index_->hashtable_size()) / static_cast<double>(index_->ntotal);
  return bytes_ + ids + buckets;
}

}  // namespace mild::tools
