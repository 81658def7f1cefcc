#include "mild_lcd/place/keyframe_database.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stamped_set.hpp"

namespace mild {

struct detail::DatabaseVote {
  FeatureId feature;
  KeyframeIndex keyframe;
  double phi;
};

// Buffers of one query, reused from feature to feature.
struct KeyframeDatabase::IndexScratch {
  struct Survivor {
    FeatureId id;
    int partial;
  };
  std::vector<FeatureId> candidates;
  std::vector<Survivor> survivors;
  // The stored features this query feature has met: a stored feature close to it shares several
  // substrings and is found in several tables. Linear in the survivors, where sorting the votes to
  // drop the copies was a third of the query on maps of many revisits.
  StampedSet met;
};

namespace {

using Vote = detail::DatabaseVote;

// Turns the votes of one query feature into per-keyframe similarity (the burstiness weighting of
// SimilarityParams) and adds them up.
class VoteAccumulator {
 public:
  VoteAccumulator(const SimilarityParams& params, KeyframeIndex keyframes, std::vector<double>& similarity)
      : params_(params), n_(keyframes), similarity_(similarity), last_feature_(keyframes, 0) {}

  void addFeatureVotes(const std::vector<Vote>& votes) {
    if (votes.empty()) return;
    ++feature_counter_;
    double weight = 1.0;
    if (params_.idf_weighting) {
      uint32_t keyframes_hit = 0;
      for (const Vote& v : votes) {
        if (last_feature_[v.keyframe] != feature_counter_) {
          last_feature_[v.keyframe] = feature_counter_;
          ++keyframes_hit;
        }
      }
      weight *= std::log(static_cast<double>(n_) / keyframes_hit);
    }
    if (params_.vote_normalization) {
      double mass = params_.burstiness_regularizer;
      for (const Vote& v : votes) mass += v.phi;
      if (!(mass > 0.0)) return;
      weight /= mass;
    }
    for (const Vote& v : votes) similarity_[v.keyframe] += weight * v.phi;
  }

 private:
  const SimilarityParams& params_;
  const KeyframeIndex n_;
  std::vector<double>& similarity_;
  std::vector<uint32_t> last_feature_;
  uint32_t feature_counter_ = 0;
};

// How many query features matched each of the first `keyframes` keyframes (a feature's several
// votes for one keyframe count once): the near-past band's evidence. vote_end[i] ends feature i's votes.
std::vector<uint32_t> matchedFeatureCounts(const std::vector<Vote>& votes, const std::vector<size_t>& vote_end,
                                           KeyframeIndex keyframes) {
  std::vector<uint32_t> matched(keyframes, 0);
  std::vector<uint32_t> last_feature(keyframes, 0);
  size_t begin = 0;
  for (size_t i = 0; i < vote_end.size(); ++i) {
    for (size_t v = begin; v < vote_end[i]; ++v) {
      const KeyframeIndex k = votes[v].keyframe;
      if (last_feature[k] != i + 1) {
        last_feature[k] = static_cast<uint32_t>(i + 1);
        ++matched[k];
      }
    }
    begin = vote_end[i];
  }
  return matched;
}

// The similarity of each of the first `keyframes` keyframes from the votes below it, feature by
// feature (VoteAccumulator's burstiness weighting).
std::vector<double> similarityFromVotes(const SimilarityParams& params, const std::vector<Vote>& votes,
                                        const std::vector<size_t>& vote_end, KeyframeIndex keyframes) {
  std::vector<double> similarity(keyframes, 0.0);
  VoteAccumulator accumulator(params, keyframes, similarity);
  std::vector<Vote> feature_votes;
  size_t begin = 0;
  for (size_t i = 0; i < vote_end.size(); ++i) {
    feature_votes.clear();
    for (size_t v = begin; v < vote_end[i]; ++v) {
      if (votes[v].keyframe < keyframes) feature_votes.push_back(votes[v]);
    }
    begin = vote_end[i];
    accumulator.addFeatureVotes(feature_votes);
  }
  return similarity;
}

}  // namespace

QueryStats& QueryStats::operator+=(const QueryStats& o) {
  query_features += o.query_features;
  buckets_probed += o.buckets_probed;
  candidates_visited += o.candidates_visited;
  early_rejections += o.early_rejections;
  repeated_candidates += o.repeated_candidates;
  full_distances += o.full_distances;
  votes += o.votes;
  return *this;
}

void DatabaseParams::validate() const {
  checkDescriptorBytes(descriptor_bytes);
  index.validate();
  similarity.validate();
}

KeyframeDatabase::KeyframeDatabase(const DatabaseParams& params)
    : params_((params.validate(), params)),
      similarity_(params.similarity.scaledTo(params.descriptor_bytes * 8)),
      phi_(similarity_),
      index_(params.index, params.descriptor_bytes * 8),
      row_words_(descriptorWords(params.descriptor_bytes)) {
  keyframe_offsets_.push_back(0);
}

void KeyframeDatabase::setSimilarityParams(const SimilarityParams& params) {
  params.validate();
  params_.similarity = params;
  similarity_ = params.scaledTo(params_.descriptor_bytes * 8);
  phi_ = PhiTable(similarity_);
}

void KeyframeDatabase::clear() {
  index_.clear();
  rows_.release();
  keyframe_offsets_.assign(1, 0);
  block_keyframe_.clear();
}

KeyframeIndex KeyframeDatabase::insert(const cv::Mat& descriptors) {
  return insert(descriptorsFromMat(descriptors, params_.descriptor_bytes));
}

void KeyframeDatabase::checkRoomFor(const DescriptorList& descriptors) const {
  checkDescriptorWidth(descriptors, params_.descriptor_bytes, "keyframe");
  const uint64_t total = static_cast<uint64_t>(featureCount()) + descriptors.size();
  if (total >= std::numeric_limits<FeatureId>::max() || size() + 1 >= kAllKeyframes) {
    throw CapacityError("keyframe database is full (2^32 features or keyframes)");
  }
}

KeyframeIndex KeyframeDatabase::insert(const DescriptorList& descriptors) {
  checkRoomFor(descriptors);
  const uint64_t total = static_cast<uint64_t>(featureCount()) + descriptors.size();
  const KeyframeIndex k = static_cast<KeyframeIndex>(size());
  const FeatureId first = static_cast<FeatureId>(featureCount());
  const size_t row_words = static_cast<size_t>(row_words_);
  if (total * row_words > rows_.capacity()) {
    // Grow by a quarter rather than double: descriptors are most of the memory, and doubling would
    // leave up to half of it unused (an extra 16 bytes per feature on average).
    const size_t capacity = rows_.capacity() / row_words;
    rows_.reserve(std::max<size_t>(total, capacity + capacity / 4 + 1024) * row_words);
  }
  size_t at = rows_.size();
  rows_.resize(at + descriptors.size() * row_words);
  uint64_t* rows = rows_.data();
  for (const Descriptor& d : descriptors) {
    for (size_t w = 0; w < row_words; ++w) rows[at++] = d.words[w];
  }
  index_.insertKeyframe(descriptors.data(), descriptors.size(), first);
  keyframe_offsets_.push_back(static_cast<FeatureId>(total));
  // Blocks that start within this keyframe's features are held by it.
  while ((static_cast<uint64_t>(block_keyframe_.size()) << kBlockShift) < total) block_keyframe_.push_back(k);
  return k;
}

KeyframeIndex KeyframeDatabase::keyframeOf(FeatureId f) const {
  // keyframe_offsets_ ascends; keyframe k owns [offsets[k], offsets[k+1]). Feature f lies between the
  // keyframe holding its block's first feature and the one holding the next block's.
  const size_t block = f >> kBlockShift;
  const auto first = keyframe_offsets_.begin() + block_keyframe_[block];
  const auto last = block + 1 < block_keyframe_.size() ? keyframe_offsets_.begin() + block_keyframe_[block + 1] + 1
                                                       : keyframe_offsets_.end();
  const auto it = std::upper_bound(first, last, f);
  return static_cast<KeyframeIndex>(it - keyframe_offsets_.begin() - 1);
}

int KeyframeDatabase::fullDistance(const Descriptor& q, FeatureId f) const {
  return hammingWords(q.words.data(), rowOf(f), row_words_);
}

void KeyframeDatabase::insertAll(const std::vector<DescriptorList>& keyframes) {
  size_t total = featureCount();
  for (const auto& k : keyframes) {
    checkDescriptorWidth(k, params_.descriptor_bytes, "keyframe");
    total += k.size();
  }
  rows_.reserve(total * static_cast<size_t>(row_words_));
  keyframe_offsets_.reserve(keyframe_offsets_.size() + keyframes.size());
  index_.deferMerges(true);
  try {
    for (const auto& k : keyframes) insert(k);
  } catch (...) {
    index_.deferMerges(false);
    throw;
  }
  index_.deferMerges(false);
}

Descriptor KeyframeDatabase::descriptor(FeatureId f) const {
  Descriptor d(params_.descriptor_bytes);
  const uint64_t* row = rowOf(f);
  std::copy(row, row + row_words_, d.words.begin());
  return d;
}

DescriptorList KeyframeDatabase::descriptors(KeyframeIndex k) const {
  DescriptorList out;
  for (FeatureId f = keyframe_offsets_[k]; f < keyframe_offsets_[k + 1]; ++f) out.push_back(descriptor(f));
  return out;
}

QueryResult KeyframeDatabase::query(const cv::Mat& q, KeyframeIndex candidate_limit, SearchMode mode) const {
  return query(descriptorsFromMat(q, params_.descriptor_bytes), candidate_limit, mode, nullptr);
}

template <int kTailWords>
void KeyframeDatabase::indexVotes(const Descriptor& f, IdRange ids, IndexScratch& scratch, std::vector<Vote>& votes,
                                  QueryStats& stats, const MihIndex::ProbePlan* plan) const {
  const SimilarityParams& sp = similarity_;
  const int d0 = sp.max_distance;
  const int tp = sp.early_termination_threshold;
  const size_t tail_words = kTailWords > 0 ? static_cast<size_t>(kTailWords) : static_cast<size_t>(row_words_ - 1);
  const uint64_t* rest = f.words.data() + 1;
  // The distance of a candidate that passed early termination (`partial` on the first word).
  const auto vote = [&](FeatureId id, int partial) {
    const uint64_t* tail = rowOf(id) + 1;
    const int d = partial + (kTailWords > 0 ? hammingWords<kTailWords>(rest, tail)
                                            : hammingWords(rest, tail, static_cast<int>(tail_words)));
    if (d <= d0) votes.push_back({id, 0, phi_(d)});
  };
  constexpr size_t kAhead = 16;
  ProbeCounters counters;
  size_t n_candidates = 0, passed = 0, distances = 0;
  if (index_.params().inline_prefixes) {
    // The first 64 bits sit beside each id in its bucket: one sequential pass, no random reads;
    // then the rows of the survivors, a few requested ahead of the one being read.
    auto& survivors = scratch.survivors;
    survivors.clear();
    index_.probeWithPrefixes(f, ids, counters, [&](FeatureId id, uint64_t prefix) {
      const int partial = popcount64(f.words[0] ^ prefix);
      if (partial <= tp) survivors.push_back({id, partial});
    });
    n_candidates = counters.entries_visited;
    passed = survivors.size();
    scratch.met.clear(passed);
    survivors.erase(std::remove_if(survivors.begin(), survivors.end(),
                                   [&](const IndexScratch::Survivor& s) { return !scratch.met.insert(s.id); }),
                    survivors.end());
    distances = survivors.size();
    for (size_t c = 0; c < survivors.size(); ++c) {
      if (c + kAhead < survivors.size()) __builtin_prefetch(rowOf(survivors[c + kAhead].id));
      vote(survivors[c].id, survivors[c].partial);
    }
  } else {
    auto& candidates = scratch.candidates;
    candidates.clear();
    if (plan != nullptr) {
      index_.gatherPlanned(*plan, ids, counters, candidates);
    } else {
      index_.gather(f, ids, counters, candidates);
    }
    // Candidates are scattered over the whole database, so each check waits for memory: the rows of
    // candidates a few steps ahead are requested while one is checked. A candidate that passes early
    // termination (and was not met already through another table) is finished at once, its row
    // still in the nearest cache: the same votes, in the same order, as checking all first.
    n_candidates = candidates.size();
    scratch.met.clear(n_candidates);
    for (size_t c = 0; c < n_candidates; ++c) {
      if (c + kAhead < n_candidates) __builtin_prefetch(rowOf(candidates[c + kAhead]));
      const FeatureId id = candidates[c];
      const int partial = popcount64(f.words[0] ^ *rowOf(id));
      if (partial > tp) continue;
      ++passed;
      if (!scratch.met.insert(id)) continue;
      ++distances;
      vote(id, partial);
    }
  }
  stats.early_rejections += n_candidates - passed;
  stats.repeated_candidates += passed - distances;
  stats.full_distances += distances;
  stats.buckets_probed += counters.buckets_probed;
  stats.candidates_visited += counters.entries_visited;
}

QueryResult KeyframeDatabase::query(const DescriptorList& q, KeyframeIndex candidate_limit, SearchMode mode,
                                    const NearPastRule* near_past) const {
  checkDescriptorWidth(q, params_.descriptor_bytes, "query");
  KeyframeIndex n = static_cast<KeyframeIndex>(std::min<size_t>(candidate_limit, size()));
  QueryResult result;
  QueryStats& stats = result.stats;
  stats.query_features = q.size();
  if (n == 0 || q.empty()) {
    result.similarity.assign(n, 0.0);
    return result;
  }

  const SimilarityParams& sp = similarity_;
  // With a near-past rule the exclusion window is read too: the band needs its matched counts. Its
  // ids are read besides the query budget, so that the eligible keyframes get the same votes as
  // without the rule (IdRange).
  const KeyframeIndex n_votes = near_past != nullptr ? static_cast<KeyframeIndex>(size()) : n;
  const FeatureId id_limit = keyframe_offsets_[n_votes];
  const IdRange ids(id_limit, keyframe_offsets_[n]);
  const int d0 = sp.max_distance;
  // First every query feature's votes (pairs within d0), then the limit (the near past may lower
  // it), then the similarity from the votes below the limit.
  std::vector<Vote> votes;
  std::vector<size_t> vote_end;
  vote_end.reserve(q.size());
  std::vector<Vote> feature_votes;
  IndexScratch scratch;
  // With a query budget the index is read in three steps (MihIndex::ProbePlan): the buckets of the
  // feature four ahead are located, those of the one two ahead prepared, while this one's are read,
  // so that each step finds what it reads already requested from memory (one ahead each was no
  // faster: docs/speed.md, "Reads requested ahead").
  const bool planned = mode == SearchMode::kIndex && index_.hasQueryBudget() && !index_.params().inline_prefixes;
  constexpr size_t kPrepareAhead = 2, kLocateAhead = 4, kPlans = kLocateAhead + 1;
  MihIndex::ProbePlan plans[kPlans];
  ProbeCounters located;
  if (planned) {
    for (size_t i = 0; i < std::min(kLocateAhead, q.size()); ++i) index_.locate(q[i], located, plans[i]);
    for (size_t i = 0; i < std::min(kPrepareAhead, q.size()); ++i) index_.prepare(plans[i]);
  }
  for (size_t i = 0; i < q.size(); ++i) {
    const Descriptor& f = q[i];
    const MihIndex::ProbePlan* plan = nullptr;
    if (planned) {
      if (i + kLocateAhead < q.size()) index_.locate(q[i + kLocateAhead], located, plans[(i + kLocateAhead) % kPlans]);
      if (i + kPrepareAhead < q.size()) index_.prepare(plans[(i + kPrepareAhead) % kPlans]);
      plan = &plans[i % kPlans];
    }
    feature_votes.clear();
    if (mode == SearchMode::kExact) {
      stats.full_distances += id_limit;
      for (FeatureId id = 0; id < id_limit; ++id) {
        const int d = fullDistance(f, id);
        if (d <= d0) feature_votes.push_back({id, 0, phi_(d)});
      }
    } else if (row_words_ == 4) {  // ORB, BRIEF: 256 bits
      indexVotes<3>(f, ids, scratch, feature_votes, stats, plan);
    } else if (row_words_ == 8) {  // BRISK, FREAK, AKAZE: up to 512 bits
      indexVotes<7>(f, ids, scratch, feature_votes, stats, plan);
    } else {
      indexVotes<0>(f, ids, scratch, feature_votes, stats, plan);
    }
    // Only votes need their keyframe, and they are few: look it up rather than store it per feature.
    for (Vote& v : feature_votes) v.keyframe = keyframeOf(v.feature);
    stats.votes += feature_votes.size();
    votes.insert(votes.end(), feature_votes.begin(), feature_votes.end());
    vote_end.push_back(votes.size());
  }

  stats.buckets_probed += located.buckets_probed;

  if (near_past != nullptr) {
    result.near_past = nearPastBand(matchedFeatureCounts(votes, vote_end, n_votes), n, *near_past);
    n -= result.near_past;
  }

  result.similarity = similarityFromVotes(sp, votes, vote_end, n);
  if (sp.normalize_by_feature_counts) divideByFeatureCounts(result.similarity, q.size());
  return result;
}

void KeyframeDatabase::divideByFeatureCounts(std::vector<double>& similarity, size_t query_features) const {
  for (KeyframeIndex k = 0; k < similarity.size(); ++k) {
    const size_t nk = featureCount(k);
    if (nk > 0) similarity[k] /= static_cast<double>(query_features) * static_cast<double>(nk);
  }
}

QueryResult KeyframeDatabase::insertAndQuery(const DescriptorList& descriptors, KeyframeIndex candidate_limit,
                                             SearchMode mode, const NearPastRule* near_past) {
  QueryResult result = query(descriptors, candidate_limit, mode, near_past);
  insert(descriptors);
  return result;
}

size_t KeyframeDatabase::memoryBytes() const {
  return index_.memoryBytes() + rows_.capacity() * sizeof(uint64_t) + keyframe_offsets_.capacity() * sizeof(FeatureId) +
         block_keyframe_.capacity() * sizeof(KeyframeIndex);
}

}  // namespace mild
