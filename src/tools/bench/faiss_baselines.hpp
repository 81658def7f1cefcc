#pragma once

#include <cstddef>
#include <memory>

#include "mild_lcd/features/descriptor.hpp"

namespace faiss {
struct IndexBinaryMultiHash;
}

namespace mild::tools {

// faiss's binary indexes over the descriptors the benchmark stores, so that the MIH kernel is
// compared with the best-kept library for the job: IndexBinaryMultiHash (multi-index hashing, one
// hash map per b-bit substring, every candidate's full distance) and the IndexBinaryFlat it keeps
// its codes in (exact search). A query asks what the keyframe database's query asks: every stored
// feature within max_distance bits of each query feature (a range search), on one thread.
class FaissBaselines {
 public:
  // `tables` substrings of bits / tables bits each (16 of ORB's 256 bits -> 16-bit substrings, as
  // mild_lcd's default). faiss takes whole bytes per code, so bits is 8 x the descriptor's bytes.
  FaissBaselines(int bits, int tables);
  ~FaissBaselines();
  FaissBaselines(const FaissBaselines&) = delete;
  FaissBaselines& operator=(const FaissBaselines&) = delete;

  void add(const DescriptorList& keyframe);
  // Both return the number of (query feature, stored feature) pairs found within max_distance.
  size_t queryMultiHash(const DescriptorList& query, int max_distance) const;
  size_t queryExact(const DescriptorList& query, int max_distance) const;
  // Bytes the multi-hash index holds per stored feature, estimated from its layout: codes, ids and
  // bucket nodes (not the vectors' spare capacity, which adds up to as much again as the ids).
  double entryBytesPerFeature() const;

 private:
  std::unique_ptr<faiss::IndexBinaryMultiHash> index_;
  int bytes_;
};

}  // namespace mild::tools
