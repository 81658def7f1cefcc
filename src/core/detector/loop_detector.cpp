#include "mild_lcd/detector/loop_detector.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stopwatch.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/detector/observation.hpp"

namespace mild {

DatabaseParams DetectorParams::databaseParams() const {
  DatabaseParams p = database;
  p.descriptor_bytes = features.descriptorBytes();
  return p;
}

void DetectorParams::validate() const {
  features.validate();
  const DatabaseParams db = databaseParams();
  db.validate();
  // The layouts the width implies: substrings of at most 64 bits (index), 20 (sparse match).
  const int bits = db.descriptor_bytes * 8;
  const int fewest = std::max(SubstringLayout::kMinSubstrings,
                              SubstringLayout::substringsFor(bits, SubstringLayout::kMaxSubstringBits));
  if (db.index.tablesFor(bits) < fewest) {
    throw InvalidInput("index/num_tables must be 0 (automatic) or at least " + std::to_string(fewest) + " for " +
                       std::to_string(bits) + "-bit descriptors (substrings of at most 64 bits), got " +
                       std::to_string(db.index.num_tables));
  }
  filter.validate();
  candidates.validate();
  if (verification.enabled) {
    verification.validate();
    verification.matching.validateFor(bits);
  }
  scoring.validate();
  if (scoring.enabled && verification.enabled && scoring.filter_type != filter.type) {
    throw InvalidInput("scoring/weights were fitted with filter/type " + scoring.filter_type +
                       " but this detector runs " + filter.type +
                       ": its probability would be miscalibrated. Refit them on runs of " + filter.type +
                       " (scripts/fit_scoring.py) and set scoring/filter_type, or set scoring/enabled false");
  }
}

LoopDetector::LoopDetector(const DetectorParams& params)
    : params_((params.validate(), params)),
      extractor_(makeFeatureExtractor(params.features)),
      database_(params.databaseParams()),
      filter_(makeTemporalFilter(params.filter)),
      scorer_(params.scoring) {
  if (params_.verification.enabled) verifier_ = std::make_unique<GeometricVerifier>(params_.verification);
}

LoopDetector::~LoopDetector() = default;

void LoopDetector::retune(const DetectorParams& next) {
  const auto now = describeParameters(params_);
  const auto wanted = describeParameters(next);
  const auto& runtime = runtimeParameterNames();
  const auto changed = [&](const std::string& section) {
    for (size_t i = 0; i < now.size(); ++i) {
      if (now[i].second != wanted[i].second && now[i].first.compare(0, section.size() + 1, section + "/") == 0)
        return true;
    }
    return false;
  };
  for (size_t i = 0; i < now.size(); ++i) {
    if (now[i].second == wanted[i].second) continue;
    if (std::find(runtime.begin(), runtime.end(), now[i].first) == runtime.end()) {
      throw InvalidInput(now[i].first + " cannot change while running (it shapes the stored map or the filter): " +
                         "set it at start-up");
    }
  }
  next.validate();
  DetectorParams retuned = params_;
  copyRuntimeParameters(next, retuned);
  // The parts built from a section are rebuilt when it changed; the candidate parameters are read
  // where they are used. A part holding the map or the filter's state cannot be rebuilt: its
  // parameters are not runtime, and the retune test (test_retune) fails when one is declared so.
  std::unique_ptr<CandidateVerifier> verifier;
  if (changed("verification") && dynamic_cast<const GeometricVerifier*>(verifier_.get()) != nullptr) {
    verifier = std::make_unique<GeometricVerifier>(retuned.verification);
  }
  if (changed("scoring")) scorer_ = CandidateScorer(retuned.scoring);
  params_ = std::move(retuned);
  if (verifier) verifier_ = std::move(verifier);
  ++retunes_;
}

void LoopDetector::reset() {
  database_.clear();
  filter_->reset();
  records_.clear();
  index_of_id_.clear();
  next_id_ = 0;
  session_start_ = 0;
  session_ = 0;
}

void LoopDetector::restore(DetectorState state, bool continue_session) {
  commitRestore(prepareRestore(std::move(state), continue_session));
}

namespace {

uint32_t largestSession(const std::vector<KeyframeRecord>& records) {
  uint32_t largest = 0;
  for (const KeyframeRecord& r : records) largest = std::max(largest, r.session);
  return largest;
}

}  // namespace

PreparedRestore LoopDetector::prepareRestore(DetectorState state, bool continue_session) const {
  const size_t n = state.records.size();
  if (state.session_start > n) throw InvalidInput("state's session start lies beyond its keyframes");
  // Resuming: the saved run's session (that of its newest keyframe, unless it had just begun a new
  // one). A new session: a number above every stored one.
  const uint32_t next_session = n == 0 ? 0 : largestSession(state.records) + 1;
  if (n > 0 && next_session == 0) throw InvalidInput("state uses the largest session number; none is left");
  if (continue_session) {
    const uint32_t session = state.session_start < n ? state.records.back().session : next_session;
    const KeyframeIndex session_start = state.session_start;
    return build(std::move(state), session_start, session, true);
  }
  return build(std::move(state), static_cast<KeyframeIndex>(n), next_session, false);
}

void LoopDetector::checkWidth(const DetectorState& state) const {
  if (state.descriptor_bytes != descriptorBytes()) {
    throw InvalidInput("the map holds " + std::to_string(state.descriptor_bytes) + "-byte descriptors, this detector " +
                       std::to_string(descriptorBytes()) + "-byte ones (features/type " + params_.features.type +
                       "): a map is only loaded by a detector with the same descriptor");
  }
}

PreparedRestore LoopDetector::prepareMerge(DetectorState state) const {
  checkWidth(state);
  const size_t added = state.records.size();
  for (const KeyframeRecord& r : state.records) {
    if (index_of_id_.count(r.id)) {
      throw InvalidInput("keyframe id " + std::to_string(r.id) +
                         " is in both maps: merging needs distinct ids (give each robot or session's Keyframe ids a "
                         "range of their own)");
    }
  }
  if (state.descriptors.size() != added) {
    throw InvalidInput("state has " + std::to_string(added) + " keyframes but " +
                       std::to_string(state.descriptors.size()) + " descriptor lists");
  }
  // The merged map's sessions are renumbered above every number in use here.
  const uint64_t base = static_cast<uint64_t>(std::max(session_, largestSession(records_))) + 1;
  if (base + largestSession(state.records) > UINT32_MAX) throw InvalidInput("too many sessions to merge");
  DetectorState combined;
  combined.next_id = std::max(next_id_, state.next_id);
  const size_t n = records_.size();
  combined.records.reserve(n + added);
  combined.descriptors.reserve(n + added);
  // Earlier sessions first, then the merged map, then the running session: its keyframes stay last.
  for (KeyframeIndex k = 0; k < session_start_; ++k) {
    combined.records.push_back(records_[k]);
    combined.descriptors.push_back(database_.descriptors(k));
  }
  for (size_t k = 0; k < added; ++k) {
    combined.records.push_back(std::move(state.records[k]));
    combined.records.back().session = static_cast<uint32_t>(base + combined.records.back().session);
    combined.descriptors.push_back(std::move(state.descriptors[k]));
  }
  for (KeyframeIndex k = session_start_; k < n; ++k) {
    combined.records.push_back(records_[k]);
    combined.descriptors.push_back(database_.descriptors(k));
  }
  const auto session_start = static_cast<KeyframeIndex>(session_start_ + added);
  return build(std::move(combined), session_start, session_, false);
}

void LoopDetector::merge(DetectorState state) { commitRestore(prepareMerge(std::move(state))); }

PreparedRestore LoopDetector::build(DetectorState state, KeyframeIndex session_start, uint32_t session,
                                    bool load_filter) const {
  const size_t n = state.records.size();
  if (state.descriptors.size() != n)
    throw InvalidInput("state has " + std::to_string(n) + " keyframes but " + std::to_string(state.descriptors.size()) +
                       " descriptor lists");
  std::unordered_map<uint64_t, KeyframeIndex> index_of_id;
  uint64_t largest_id = 0;
  for (size_t k = 0; k < n; ++k) {
    const KeyframeRecord& r = state.records[k];
    if (r.keypoints.size() != state.descriptors[k].size()) {
      throw InvalidInput("keyframe " + std::to_string(r.id) + " has " + std::to_string(r.keypoints.size()) +
                         " keypoints but " + std::to_string(state.descriptors[k].size()) + " descriptors");
    }
    if (!std::isfinite(r.stamp)) throw InvalidInput("keyframe " + std::to_string(r.id) + " has a non-finite stamp");
    if (r.id > kMaxKeyframeId) throw InvalidInput("keyframe id " + std::to_string(r.id) + " is above the largest id");
    if (!r.camera.wellFormed()) throw InvalidInput("keyframe " + std::to_string(r.id) + " has malformed intrinsics");
    if (!index_of_id.emplace(r.id, static_cast<KeyframeIndex>(k)).second) {
      throw InvalidInput("keyframe id " + std::to_string(r.id) + " appears twice");
    }
    largest_id = std::max(largest_id, r.id);
  }
  if (n > 0 && state.next_id <= largest_id) throw InvalidInput("state's next id is not above its largest keyframe id");

  checkWidth(state);
  KeyframeDatabase database(params_.databaseParams());
  database.insertAll(state.descriptors);
  std::unique_ptr<TemporalFilter> filter = makeTemporalFilter(params_.filter);
  if (load_filter) {
    if (state.filter_name != filter->name()) {
      throw InvalidInput("the saved run used filter/type '" + state.filter_name + "', this detector runs '" +
                         filter->name() + "': load it as a new session (continue_session false), or run '" +
                         state.filter_name + "' to resume it");
    }
    filter->loadState(state.filter_state);
    if (filter->stateKeyframes() > n) throw InvalidInput("filter state covers more keyframes than the database holds");
  }
  return PreparedRestore{std::move(database),
                         std::move(filter),
                         std::move(state.records),
                         std::move(index_of_id),
                         state.next_id,
                         session_start,
                         session};
}

void LoopDetector::commitRestore(PreparedRestore&& prepared) {
  database_ = std::move(prepared.database);
  filter_ = std::move(prepared.filter);
  records_ = std::move(prepared.records);
  index_of_id_ = std::move(prepared.index_of_id);
  next_id_ = prepared.next_id;
  session_start_ = prepared.session_start;
  session_ = prepared.session;
}

std::optional<KeyframeIndex> LoopDetector::find(uint64_t id) const {
  auto it = index_of_id_.find(id);
  if (it == index_of_id_.end()) return std::nullopt;
  return it->second;
}

Features LoopDetector::features(KeyframeIndex k) const {
  return Features{records_[k].keypoints, database_.descriptors(k), records_[k].camera, {}};
}

size_t LoopDetector::memoryBytes() const {
  size_t bytes = database_.memoryBytes() + records_.capacity() * sizeof(KeyframeRecord);
  for (const auto& r : records_) bytes += r.keypoints.capacity() * sizeof(cv::KeyPoint);
  return bytes + index_of_id_.size() * (sizeof(uint64_t) + sizeof(KeyframeIndex) + 2 * sizeof(void*));
}

KeyframeIndex LoopDetector::eligibleCount(double stamp) const {
  // The query will be keyframe n; keyframe j may be a candidate when n - j >= exclusion_frames.
  const size_t n = records_.size();
  const size_t frames = static_cast<size_t>(params_.candidates.exclusion_frames);
  size_t limit = frames == 0 ? n : (n + 1 > frames ? n + 1 - frames : 0);
  if (limit <= session_start_) return session_start_;  // earlier sessions are never "a moment ago"
  if (params_.candidates.exclusion_seconds > 0.0) {
    // Keyframes are stored in arrival order; stamps are expected to grow, so the eligible set is a prefix.
    const double newest_allowed = stamp - params_.candidates.exclusion_seconds;
    const auto end = records_.begin() + static_cast<long>(limit);
    limit = static_cast<size_t>(std::upper_bound(records_.begin(), end, newest_allowed,
                                                 [](double s, const KeyframeRecord& r) { return s < r.stamp; }) -
                                records_.begin());
    limit = std::max<size_t>(limit, session_start_);
  }
  return static_cast<KeyframeIndex>(limit);
}

void LoopDetector::checkId(std::optional<uint64_t> id) const {
  if (id) {
    if (*id > kMaxKeyframeId) {
      throw InvalidInput("keyframe id " + std::to_string(*id) + " is too large (ids must be below 2^64 - 1)");
    }
    if (index_of_id_.count(*id))
      throw InvalidInput("keyframe id " + std::to_string(*id) + " is already in the database");
  } else if (next_id_ > kMaxKeyframeId) {
    throw CapacityError("no keyframe id left to assign (the largest id in use is 2^64 - 2): give ids explicitly");
  }
}

DetectionResult LoopDetector::process(const cv::Mat& image, PixelFormat format, double stamp,
                                      std::optional<uint64_t> id, const CameraIntrinsics& camera,
                                      const std::vector<OtherMap>& others, uint32_t robot) {
  checkId(id);
  Observation extracted =
      extractFeatures(Observation::ofImage(image, format, stamp, id, camera), *extractor_, descriptorBytes());
  DetectionResult result = process(std::move(extracted.features), stamp, id, others, robot);
  result.stats.extract_ms = extracted.extract_ms;
  return result;
}

MapScope LoopDetector::ownScope(double stamp) const {
  MapScope scope;
  scope.eligible = eligibleCount(stamp);
  const CandidateParams& cp = params_.candidates;
  if (cp.near_past) {
    NearPastRule near_past;
    near_past.rise = cp.near_past_rise;
    near_past.floor = session_start_;
    scope.near_past = near_past;
  }
  return scope;
}

MapAnswer LoopDetector::queryMap(const DescriptorList& query, const MapScope& scope, TemporalFilter& filter,
                                 size_t max_candidates) const {
  MapAnswer answer;
  auto start = Clock::now();
  answer.query = database_.query(query, scope.eligible, params_.search, scope.near_past ? &*scope.near_past : nullptr);
  answer.query_ms = msSince(start);
  start = Clock::now();
  const std::vector<double>& belief = filter.update(answer.query.similarity);
  const std::vector<double>& similarity = answer.query.similarity;
  const std::vector<double> saliency = robustSaliency(similarity);
  const auto radius = static_cast<KeyframeIndex>(params_.candidates.suppression_radius);
  const auto add = [&](KeyframeIndex j) {
    for (const LoopCandidate& taken : answer.candidates) {
      if (taken.index == j) return;
    }
    LoopCandidate c;
    c.index = j;
    c.id = records_[j].id;
    c.session = records_[j].session;
    c.stamp = records_[j].stamp;
    c.filter_probability = belief[j];
    c.probability = belief[j];
    c.similarity = similarity[j];
    c.saliency = saliency[j];
    c.eligible_keyframes = similarity.size();
    answer.candidates.push_back(c);
  };
  // The filter's best, then the most similar: evidence the filter's belief passed over is still
  // verified and judged on its own (the scorer weighs both).
  for (KeyframeIndex j : separatedBest(belief, similarity, max_candidates, radius)) add(j);
  const auto similar = static_cast<size_t>(params_.candidates.similarity_candidates);
  if (similar > 0) {
    for (KeyframeIndex j : separatedBest(similarity, similarity, similar, radius)) add(j);
  }
  answer.filter_ms = msSince(start);
  return answer;
}

DetectionResult LoopDetector::process(Features features, double stamp, std::optional<uint64_t> id,
                                      const std::vector<OtherMap>& others, uint32_t robot) {
  if (features.keypoints.size() != features.descriptors.size()) {
    throw InvalidInput("keyframe has " + std::to_string(features.keypoints.size()) + " keypoints but " +
                       std::to_string(features.descriptors.size()) + " descriptors");
  }
  checkCameraAndDepths(features);
  const auto refuseWidth = [&](int bytes) {
    if (bytes == descriptorBytes()) return;
    throw InvalidInput("keyframe descriptors are " + std::to_string(bytes) + " bytes wide; this database holds " +
                       std::to_string(descriptorBytes()) + "-byte descriptors (features/type " + params_.features.type +
                       ")");
  };
  if (features.declared_bytes != 0) refuseWidth(features.declared_bytes);  // judged even without descriptors
  for (const Descriptor& d : features.descriptors) refuseWidth(d.bytes);
  checkId(id);
  if (!std::isfinite(stamp)) throw InvalidInput("keyframe stamp is not a finite number");
  database_.checkRoomFor(features.descriptors);  // before the filter moves on
  DetectionResult result;
  result.query_id = id ? *id : next_id_;
  result.query_robot = robot;
  result.stats.features = features.descriptors.size();
  const size_t max_candidates = static_cast<size_t>(params_.candidates.max_candidates);

  // This map, then the others: each the same step, each through its own filter.
  MapAnswer own = queryMap(features.descriptors, ownScope(stamp), *filter_, max_candidates);
  result.stats.query_ms = own.query_ms;
  result.stats.filter_ms = own.filter_ms;
  result.stats.query = own.query.stats;
  result.stats.eligible_keyframes = own.query.similarity.size();
  result.stats.near_past_keyframes = own.query.near_past;
  std::vector<const LoopDetector*> maps(own.candidates.size(), this);
  for (LoopCandidate& c : own.candidates) c.robot = robot;
  result.candidates = std::move(own.candidates);
  for (const OtherMap& other : others) {
    if (other.map->size() == 0) continue;
    MapAnswer answer = other.map->queryMap(features.descriptors, MapScope{}, *other.filter, max_candidates);
    result.stats.query_ms += answer.query_ms;
    result.stats.query += answer.query.stats;
    result.stats.filter_ms += answer.filter_ms;
    for (LoopCandidate& c : answer.candidates) {
      c.robot = other.robot;
      result.candidates.push_back(std::move(c));
      maps.push_back(other.map);
    }
  }

  auto start = Clock::now();
  judge(result.candidates, features, maps);
  // max_candidates is per keyframe, however many maps were asked: the best after scoring.
  if (result.candidates.size() > max_candidates) {
    result.unreported.assign(std::make_move_iterator(result.candidates.begin() + static_cast<long>(max_candidates)),
                             std::make_move_iterator(result.candidates.end()));
    result.candidates.resize(max_candidates);
  }
  if (verifier_ && !result.candidates.empty()) result.stats.verify_ms = msSince(start);

  // Stored last: the query is never its own candidate, and a refusal above changes nothing.
  start = Clock::now();
  database_.insert(features.descriptors);
  result.stats.query_ms += msSince(start);
  result.query_index = static_cast<KeyframeIndex>(records_.size());
  result.query_session = session_;
  records_.push_back(KeyframeRecord{result.query_id, stamp, session_, std::move(features.keypoints), features.camera});
  index_of_id_.emplace(result.query_id, result.query_index);
  next_id_ = std::max(next_id_, result.query_id + 1);
  result.similarity = std::move(own.query.similarity);
  return result;
}

void LoopDetector::judge(std::vector<LoopCandidate>& candidates, const Features& query,
                         const std::vector<const LoopDetector*>& maps) const {
  if (verifier_ && !candidates.empty()) {
    std::vector<Features> candidate_features;
    candidate_features.reserve(candidates.size());
    for (size_t i = 0; i < candidates.size(); ++i) candidate_features.push_back(maps[i]->features(candidates[i].index));
    CandidateVerifier::NeedsFit needs_fit;
    if (params_.verification.early_stop) {
      needs_fit = [&](size_t i, int matches, const std::vector<Verification>& earlier) {
        return fitCanMatter(candidates, i, matches, earlier);
      };
    }
    std::vector<Verification> verifications = verifier_->verifyAll(query, candidate_features, needs_fit);
    if (verifications.size() != candidates.size()) {
      throw std::logic_error("the candidate verifier returned " + std::to_string(verifications.size()) +
                             " verifications for " + std::to_string(candidates.size()) + " candidates");
    }
    for (size_t i = 0; i < candidates.size(); ++i) candidates[i].verification = std::move(verifications[i]);
  }
  for (LoopCandidate& c : candidates) {
    c.probability = publishedProbability(c, c.verification);
    c.accepted = c.probability >= params_.scoring.decision_probability;
  }
  rankCandidates(candidates, params_.candidates.min_probability);
}

double LoopDetector::publishedProbability(const LoopCandidate& c, const Verification& v) const {
  if (!verifier_) return c.filter_probability;
  const double p = scorer_.probability(evidenceOf(c), v);
  return v.verified ? p : belowDecision(p, params_.scoring.decision_probability);
}

bool LoopDetector::fitCanMatter(const std::vector<LoopCandidate>& candidates, size_t i, int matches,
                                const std::vector<Verification>& earlier) const {
  // The published probability as a function of the inliers, at its highest over 0..matches (the
  // inliers are a subset of the matches; the scorer is monotone in them, either way).
  Verification none, all;
  all.inliers = matches;
  all.verified = true;  // the best case: every match an inlier, and verified
  const LoopCandidate& c = candidates[i];
  const double reachable = std::max(publishedProbability(c, none), publishedProbability(c, all));
  if (reachable >= params_.scoring.decision_probability) return true;  // it could be accepted
  // Below the decision either way: it matters only if it could outrank the query's best so far,
  // which is all the evaluation (and a consumer taking the best candidate) reads.
  for (size_t k = 0; k < earlier.size(); ++k) {
    if (publishedProbability(candidates[k], earlier[k]) > reachable) return false;
  }
  return true;
}

void rankCandidates(std::vector<LoopCandidate>& candidates, double min_probability) {
  // Best first by the published probability (the filter's order among equals), at least
  // detector/min_probability.
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const LoopCandidate& a, const LoopCandidate& b) { return a.probability > b.probability; });
  candidates.erase(std::remove_if(candidates.begin(), candidates.end(),
                                  [&](const LoopCandidate& c) { return c.probability < min_probability; }),
                   candidates.end());
}

std::vector<KeyframeIndex> separatedBest(const std::vector<double>& belief, const std::vector<double>& similarity,
                                         size_t max_count, KeyframeIndex suppression_radius) {
  std::vector<KeyframeIndex> order;
  for (KeyframeIndex j = 0; j < belief.size(); ++j) {
    if (belief[j] > 0.0) order.push_back(j);
  }
  const auto better = [&](KeyframeIndex a, KeyframeIndex b) {
    if (belief[a] != belief[b]) return belief[a] > belief[b];
    if (similarity[a] != similarity[b]) return similarity[a] > similarity[b];
    return a < b;
  };
  // Sorted a batch at a time, as far as the walk gets: sorting every keyframe was most of the
  // filter stage on large maps (O(N log N) beside the filter's O(N)).
  constexpr size_t kFirstBatch = 64;
  size_t sorted = 0;
  std::vector<KeyframeIndex> out;
  for (size_t i = 0; i < order.size() && out.size() < max_count; ++i) {
    if (i == sorted) {
      sorted = std::min(order.size(), std::max(kFirstBatch, 2 * sorted));
      std::partial_sort(order.begin() + static_cast<long>(i), order.begin() + static_cast<long>(sorted), order.end(),
                        better);
    }
    const KeyframeIndex j = order[i];
    const bool suppressed = std::any_of(out.begin(), out.end(), [&](KeyframeIndex taken) {
      return (taken > j ? taken - j : j - taken) <= suppression_radius;
    });
    if (!suppressed) out.push_back(j);
  }
  return out;
}

}  // namespace mild
