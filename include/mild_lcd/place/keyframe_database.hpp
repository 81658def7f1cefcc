#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/common/mapped_array.hpp"
#include "mild_lcd/common/types.hpp"
#include "mild_lcd/features/descriptor.hpp"
#include "mild_lcd/index/mih_index.hpp"
#include "mild_lcd/place/near_past.hpp"
#include "mild_lcd/place/similarity.hpp"

namespace mild {
namespace detail {
struct DatabaseVote;  // a (query feature, stored feature) pair within d0 and its phi
}  // namespace detail

enum class SearchMode {
  kIndex,  // candidates from the MIH tables (the method)
  kExact,  // every stored feature is a candidate: brute force, the accuracy ceiling
};

// What one query did. candidates_visited counts index entries read, so a stored feature that meets
// the query feature in k tables counts k times; votes counts distinct (query, stored) feature pairs
// within d0 that voted.
struct QueryStats {
  uint64_t query_features = 0;
  uint64_t buckets_probed = 0;
  uint64_t candidates_visited = 0;
  uint64_t early_rejections = 0;
  // Passed early termination but were met already in another table (a close stored feature shares
  // several substrings with the query feature): compared and voted once.
  uint64_t repeated_candidates = 0;
  uint64_t full_distances = 0;
  uint64_t votes = 0;

  QueryStats& operator+=(const QueryStats& o);
};

struct QueryResult {
  std::vector<double> similarity;  // Phi'(query, k) for every keyframe k below the candidate limit
  KeyframeIndex near_past = 0;     // keyframes the NearPastRule removed from the candidate limit
  QueryStats stats;
};

struct DatabaseParams {
  // The width of the descriptors the database holds (32 bytes for ORB, 64 for BRISK, 61 for
  // AKAZE). Not a parameter of its own: the detector takes it from its feature source.
  int descriptor_bytes = kOrbDescriptorBytes;
  MihParams index;
  SimilarityParams similarity;
  void validate() const;
};

// The keyframe database: descriptors of every inserted keyframe, the MIH index over them, and
// image similarity by voting. Keyframes are numbered 0, 1, 2, ... in insertion order.
//
// Descriptors are stored one row per feature (4 words for ORB, 8 for BRISK); early termination
// looks at a candidate's first word and reads the rest only when it passes, from the same cache
// line. Every descriptor must have the database's width (DatabaseParams::descriptor_bytes).
class KeyframeDatabase {
 public:
  explicit KeyframeDatabase(const DatabaseParams& params = {});

  const DatabaseParams& params() const { return params_; }
  // The similarity parameters at this database's width (SimilarityParams::scaledTo).
  const SimilarityParams& similarity() const { return similarity_; }
  // Similarity parameters do not shape the index, so they can change at any time (live tuning).
  // Throws InvalidInput, changing nothing, when they are invalid.
  void setSimilarityParams(const SimilarityParams& params);

  // Adds a keyframe and returns its index. Throws InvalidInput (and adds nothing) when a descriptor
  // is not of the database's width (the cv::Mat overload: unless the matrix is N x width CV_8U). A
  // keyframe may have no features.
  KeyframeIndex insert(const DescriptorList& descriptors);
  // What insert() checks first, so that a caller can refuse a keyframe before changing anything
  // else: InvalidInput for another width, CapacityError when 2^32 features or keyframes are reached.
  void checkRoomFor(const DescriptorList& descriptors) const;
  KeyframeIndex insert(const cv::Mat& descriptors);
  // Many keyframes at once, in order (loading a saved database): the same result as inserting them
  // one by one, with a single merge of the index at the end. Checks every width before adding any.
  void insertAll(const std::vector<DescriptorList>& keyframes);

  // Similarity of the query to every keyframe k < candidate_limit (all keyframes by default). Throws
  // InvalidInput when the query's descriptors are not of the database's width.
  // Keyframes at or beyond the limit take no part: they neither receive votes nor count in N or N_f.
  // With a NearPastRule, the limit is lowered by the near-past band first (the similarity vector is
  // then shorter by near_past).
  QueryResult query(const DescriptorList& query, KeyframeIndex candidate_limit = kAllKeyframes,
                    SearchMode mode = SearchMode::kIndex, const NearPastRule* near_past = nullptr) const;
  QueryResult query(const cv::Mat& query, KeyframeIndex candidate_limit = kAllKeyframes,
                    SearchMode mode = SearchMode::kIndex) const;

  // query() against the keyframes stored so far, then insert(). The new keyframe's index is size()-1
  // afterwards.
  QueryResult insertAndQuery(const DescriptorList& descriptors, KeyframeIndex candidate_limit = kAllKeyframes,
                             SearchMode mode = SearchMode::kIndex, const NearPastRule* near_past = nullptr);

  int descriptorBytes() const { return params_.descriptor_bytes; }
  size_t size() const { return keyframe_offsets_.size() - 1; }
  size_t featureCount() const { return rows_.size() / static_cast<size_t>(row_words_); }
  size_t featureCount(KeyframeIndex k) const { return keyframe_offsets_[k + 1] - keyframe_offsets_[k]; }
  FeatureId firstFeature(KeyframeIndex k) const { return keyframe_offsets_[k]; }
  KeyframeIndex keyframeOf(FeatureId f) const;
  Descriptor descriptor(FeatureId f) const;
  DescriptorList descriptors(KeyframeIndex k) const;

  const MihIndex& index() const { return index_; }
  size_t memoryBytes() const;
  void clear();

 private:
  // Phi' / (|F_query| |F_keyframe|): similarity/normalize_by_feature_counts.
  void divideByFeatureCounts(std::vector<double>& similarity, size_t query_features) const;
  struct IndexScratch;
  using Vote = detail::DatabaseVote;
  int fullDistance(const Descriptor& q, FeatureId f) const;
  const uint64_t* rowOf(FeatureId f) const { return rows_.data() + static_cast<size_t>(f) * row_words_; }
  // The query of one feature through the index: its votes (pairs within d0) into `votes` (empty),
  // with the tails' word count known at compile time where it can be (kTailWords 0: read at run
  // time), so that ORB's and BRISK's distances are unrolled loops.
  template <int kTailWords>
  // `plan`: its buckets located and prepared ahead (MihIndex::ProbePlan), or null to probe here.
  void indexVotes(const Descriptor& f, IdRange ids, IndexScratch& scratch, std::vector<Vote>& votes, QueryStats& stats,
                  const MihIndex::ProbePlan* plan) const;

  DatabaseParams params_;
  SimilarityParams similarity_;
  PhiTable phi_;
  MihIndex index_;
  int row_words_ = 0;  // 64-bit words per feature
  // Every feature's descriptor, row after row. One row, not the first words in an array of their own:
  // a candidate costs one random read from memory (a row of ORB is 32 bytes, half a cache line,
  // never split across two: the array is page aligned), and the third of candidates that pass early
  // termination find the rest of their descriptor in the line already read. With the first words
  // apart, each survivor cost a second miss (docs/speed.md, "One row per descriptor").
  MappedArray<uint64_t> rows_;
  std::vector<FeatureId> keyframe_offsets_;  // keyframe k owns features [offsets[k], offsets[k+1])
  // Every vote needs its keyframe: a binary search over keyframe_offsets_ per vote cost 9% of a query
  // at 1,000 keyframes. block_keyframe_[b] is the keyframe holding feature b << kBlockShift, so a lookup searches only
  // the few keyframes within one block.
  static constexpr int kBlockShift = 8;
  std::vector<KeyframeIndex> block_keyframe_;
};

}  // namespace mild
