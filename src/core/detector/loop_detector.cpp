#include "mild_lcd/detector/loop_detector.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stopwatch.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/verification/chance_agreement.hpp"

namespace mild {

namespace {

// The "name: value" lines a map is saved with (KeyframeMap::builderParameters).
std::string parameterText(const DetectorParams& params) {
  std::string text;
  for (const auto& [name, value] : describeParameters(params)) text += name + ": " + value + "\n";
  return text;
}

// Where a detector's descriptor width comes from, as errors name it.
std::string widthSource(const FeatureParams& features) {
  if (features.descriptor_bytes > 0) return "features/descriptor_bytes " + std::to_string(features.descriptor_bytes);
  return "features/type " + features.type;
}

}  // namespace

LoopDetector::LoopDetector(const DetectorParams& params)
    : params_((params.validate(), params)),
      map_(params.databaseParams(), params.filter, widthSource(params.features)),
      scorer_(params.scoring) {
  map_.setBuilderParameters(parameterText(params_));
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
  map_.setBuilderParameters(parameterText(params_));
  ++retunes_;
}

MapScope LoopDetector::ownScope(double stamp) const {
  MapScope scope;
  const CandidateParams& cp = params_.candidates;
  scope.eligible = map_.eligibleCount(stamp, cp.exclusion_frames, cp.exclusion_seconds);
  if (cp.near_past) {
    NearPastRule near_past;
    near_past.rise = cp.near_past_rise;
    near_past.floor = map_.sessionStart();
    scope.near_past = near_past;
  }
  return scope;
}

MapAnswer LoopDetector::queryMap(const KeyframeMap& map, const DescriptorList& query, const MapScope& scope,
                                 TemporalFilter& filter, size_t max_candidates) const {
  MapAnswer answer;
  auto start = Clock::now();
  answer.query =
      map.database().query(query, scope.eligible, params_.search, scope.near_past ? &*scope.near_past : nullptr);
  answer.query_ms = msSince(start);
  start = Clock::now();
  const std::vector<double>& belief = filter.update(answer.query.similarity);
  // The candidates and their saliency come from what the filter weighed (a hub-corrected filter's
  // evidence, or the similarity); a candidate's published similarity is the similarity itself.
  const std::vector<double>& raw = answer.query.similarity;
  const std::vector<double>& similarity = filter.evidence() != nullptr ? *filter.evidence() : raw;
  const std::vector<double> saliency = robustSaliency(similarity);
  const auto radius = static_cast<KeyframeIndex>(params_.candidates.suppression_radius);
  const auto add = [&](KeyframeIndex j) {
    for (const LoopCandidate& taken : answer.candidates) {
      if (taken.index == j) return;
    }
    LoopCandidate c;
    c.index = j;
    const KeyframeRecord& record = map.record(j);
    c.id = record.id;
    c.session = record.session;
    c.stamp = record.stamp;
    c.filter_probability = belief[j];
    c.probability = belief[j];
    c.similarity = raw[j];
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

bool LoopDetector::takeWidth(int bytes) {
  if (bytes == map_.descriptorBytes() || map_.size() > 0 || params_.features.descriptor_bytes > 0) return false;
  DetectorParams at_width = params_;
  at_width.features.descriptor_bytes = bytes;
  at_width.validate();  // the width's bounds, and the index's and matcher's layouts at it
  KeyframeMap map(at_width.databaseParams(), params_.filter,
                  "the " + std::to_string(bytes) + "-byte descriptors " + "its first keyframe brought");
  map.setBuilderParameters(parameterText(at_width));
  map_ = std::move(map);
  return true;
}

void LoopDetector::checkFeatures(const Features& features) const {
  if (features.keypoints.size() != features.descriptors.size()) {
    throw InvalidInput("keyframe has " + std::to_string(features.keypoints.size()) + " keypoints but " +
                       std::to_string(features.descriptors.size()) + " descriptors");
  }
  checkCameraAndDepths(features);
  const auto refuseWidth = [&](int bytes) {
    if (bytes == map_.descriptorBytes()) return;
    throw InvalidInput("keyframe descriptors are " + std::to_string(bytes) + " bytes wide; this database holds " +
                       std::to_string(map_.descriptorBytes()) + "-byte descriptors (" + map_.descriptorSource() +
                       "): set " + descriptorSetting(bytes) + " for these");
  };
  if (features.declared_bytes != 0) refuseWidth(features.declared_bytes);  // judged even without descriptors
  for (const Descriptor& d : features.descriptors) refuseWidth(d.bytes);
}

DetectionResult LoopDetector::process(Observation observation, const std::vector<OtherMap>& others, uint32_t robot) {
  if (observation.image) {
    throw InvalidInput("the detector takes features: extract the image's first (FeatureFrontEnd::extract)");
  }
  Features& features = observation.features;
  const double stamp = observation.stamp;
  const std::optional<uint64_t> id = observation.id;
  checkFeatures(features);
  map_.checkId(id);
  if (!std::isfinite(stamp)) throw InvalidInput("keyframe stamp is not a finite number");
  map_.checkRoomFor(features.descriptors);  // before the filter moves on
  DetectionResult result;
  result.query_id = id ? *id : map_.nextId();
  result.query_robot = robot;
  result.stats.extract_ms = observation.extract_ms;
  result.stats.features = features.descriptors.size();
  result.stats.depths_out_of_range = depthsOutOfRange(features.depths);
  result.stats.clock_stepped_back = map_.sessionClock().stepsBack(stamp);
  const size_t max_candidates = static_cast<size_t>(params_.candidates.max_candidates);

  // This map, then the others: each the same step, each through its own filter.
  MapAnswer own = queryMap(map_, features.descriptors, ownScope(stamp), map_.filter(), max_candidates);
  result.stats.query_ms = own.query_ms;
  result.stats.filter_ms = own.filter_ms;
  result.stats.query = own.query.stats;
  result.stats.eligible_keyframes = own.query.similarity.size();
  result.stats.near_past_keyframes = own.query.near_past;
  std::vector<const KeyframeMap*> maps(own.candidates.size(), &map_);
  for (LoopCandidate& c : own.candidates) c.robot = robot;
  result.candidates = std::move(own.candidates);
  for (const OtherMap& other : others) {
    if (other.map->size() == 0) continue;
    MapAnswer answer = queryMap(*other.map, features.descriptors, MapScope{}, *other.filter, max_candidates);
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
  judge(result.candidates, &features, maps);
  // max_candidates is per keyframe, however many maps were asked: the best after scoring.
  if (result.candidates.size() > max_candidates) {
    result.unreported.assign(std::make_move_iterator(result.candidates.begin() + static_cast<long>(max_candidates)),
                             std::make_move_iterator(result.candidates.end()));
    result.candidates.resize(max_candidates);
  }
  if (verifier_ && !result.candidates.empty()) result.stats.verify_ms = msSince(start);

  // Stored last: the query is never its own candidate, and a refusal above changes nothing.
  start = Clock::now();
  result.query_session = map_.session();
  result.query_index = map_.add(result.query_id, stamp, std::move(features.keypoints), features.descriptors,
                                features.camera, features.detection_scale);
  // The place this keyframe shows, if it was found: a later query that sees both is a revisit of
  // one place, not a place that repeats (otherPlaceSignificance).
  for (const LoopCandidate& c : result.candidates) {
    if (c.robot != robot) continue;  // another robot's map
    if (c.verification.verified && c.probability >= kSamePlaceProbability) map_.markSamePlace(result.query_index, c.id);
    break;
  }
  result.stats.query_ms += msSince(start);
  result.similarity = std::move(own.query.similarity);
  return result;
}

void LoopDetector::judge(std::vector<LoopCandidate>& candidates, const Features* query,
                         const std::vector<const KeyframeMap*>& maps) const {
  if (verifier_ && query && !candidates.empty()) {
    std::vector<Features> candidate_features;
    candidate_features.reserve(candidates.size());
    for (size_t i = 0; i < candidates.size(); ++i) candidate_features.push_back(maps[i]->features(candidates[i].index));
    // The distinct places are verified on purpose, before early stop may skip anything: another
    // place's significance is then the same whether early stop is on or off.
    const std::vector<bool> on_purpose = verifiedOnPurpose(maps);
    const bool early_stop = params_.verification.early_stop;
    const CandidateVerifier::NeedsFit needs_fit = [&](size_t i, int matches, const std::vector<Verification>& earlier) {
      if (on_purpose[i] || !early_stop) return true;
      // Each map's candidates verified on purpose come first among its own, so they are all in
      // `earlier` by now: the candidates' other places are known.
      for (size_t k = 0; k <= i; ++k) {
        candidates[k].other_place_significance = otherPlaceSignificance(candidates, k, maps, on_purpose, earlier);
      }
      return fitCanMatter(candidates, i, matches, earlier);
    };
    std::vector<Verification> verifications = verifier_->verifyAll(*query, candidate_features, needs_fit);
    if (verifications.size() != candidates.size()) {
      throw std::logic_error("the candidate verifier returned " + std::to_string(verifications.size()) +
                             " verifications for " + std::to_string(candidates.size()) + " candidates");
    }
    for (size_t i = 0; i < candidates.size(); ++i) {
      candidates[i].other_place_significance = otherPlaceSignificance(candidates, i, maps, on_purpose, verifications);
    }
    for (size_t i = 0; i < candidates.size(); ++i) candidates[i].verification = std::move(verifications[i]);
  }
  for (LoopCandidate& c : candidates) {
    c.probability = publishedProbability(c, c.verification);
    c.accepted = c.probability >= params_.scoring.decision_probability;
  }
  rankCandidates(candidates, params_.candidates.min_probability);
}

namespace {

// Keyframe k and the keyframes it was found to show, one after another (KeyframeRecord::same_place_as):
// a third visit of a place was found to show the second, which showed the first.
std::vector<KeyframeIndex> placeChain(const KeyframeMap& map, KeyframeIndex k) {
  constexpr size_t kMostVisits = 16;
  std::vector<KeyframeIndex> chain{k};
  while (chain.size() < kMostVisits) {
    const std::optional<uint64_t> next = map.record(chain.back()).same_place_as;
    if (!next) break;
    const std::optional<KeyframeIndex> index = map.find(*next);
    if (!index || std::find(chain.begin(), chain.end(), *index) != chain.end()) break;
    chain.push_back(*index);
  }
  return chain;
}

}  // namespace

bool samePlace(const KeyframeMap& map, KeyframeIndex a, KeyframeIndex b, KeyframeIndex gap) {
  for (KeyframeIndex x : placeChain(map, a)) {
    for (KeyframeIndex y : placeChain(map, b)) {
      if ((x > y ? x - y : y - x) <= gap) return true;
    }
  }
  return false;
}

std::vector<bool> LoopDetector::verifiedOnPurpose(const std::vector<const KeyframeMap*>& maps) const {
  std::vector<bool> on_purpose(maps.size(), false);
  const auto wanted = static_cast<size_t>(params_.scoring.distinct_places);
  for (size_t i = 0; i < maps.size(); ++i) {
    size_t before = 0;
    for (size_t k = 0; k < i; ++k) before += maps[k] == maps[i] ? 1 : 0;
    on_purpose[i] = before < wanted;
  }
  return on_purpose;
}

double LoopDetector::otherPlaceSignificance(const std::vector<LoopCandidate>& candidates, size_t i,
                                            const std::vector<const KeyframeMap*>& maps,
                                            const std::vector<bool>& on_purpose,
                                            const std::vector<Verification>& verifications) const {
  const auto gap = static_cast<KeyframeIndex>(params_.scoring.distinct_place_gap);
  double most = 0.0;
  for (size_t j = 0; j < verifications.size(); ++j) {
    // Another robot's map showing the place too is the place seen twice, not a repetition of it.
    if (j == i || !on_purpose[j] || maps[j] != maps[i]) continue;
    // Another session's keyframe (a map loaded or merged) may show the place again; so may one the
    // detector found to show it when it was stored.
    if (candidates[j].session != candidates[i].session) continue;
    if (samePlace(*maps[i], candidates[i].index, candidates[j].index, gap)) continue;
    most = std::max(most, significanceOf(verifications[j]));
  }
  return most;
}

double LoopDetector::publishedProbability(const LoopCandidate& c, const Verification& v) const {
  if (!verifier_) return c.filter_probability;
  const double p = scorer_.probability(evidenceOf(c), v);
  return v.verified ? p : belowDecision(p, params_.scoring.decision_probability);
}

double LoopDetector::reachableProbability(const LoopCandidate& c, int matches) const {
  // The published probability as a function of the inliers, at its highest over 0..matches (the
  // inliers are a subset of the matches; the scorer is monotone in them, either way).
  Verification none, all;
  all.inliers = matches;
  all.verified = true;  // the best case: every match an inlier, and verified, at the smallest chance
  all.log10_false_alarms = log10FalseAlarms(matches, matches, kLeastChanceInlierProbability, kEssentialSample);
  return std::max(publishedProbability(c, none), publishedProbability(c, all));
}

bool LoopDetector::couldBeAccepted(const LoopCandidate& c, int matches) const {
  return reachableProbability(c, matches) >= params_.scoring.decision_probability;
}

bool LoopDetector::fitCanMatter(const std::vector<LoopCandidate>& candidates, size_t i, int matches,
                                const std::vector<Verification>& earlier) const {
  const double reachable = reachableProbability(candidates[i], matches);
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
