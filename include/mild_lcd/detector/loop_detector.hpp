#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/detector/candidate_scorer.hpp"
#include "mild_lcd/detector/detection_result.hpp"
#include "mild_lcd/detector/detector_params.hpp"
#include "mild_lcd/detector/observation.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/filter/filters.hpp"
#include "mild_lcd/params/parameter_spec.hpp"
#include "mild_lcd/place/keyframe_database.hpp"
#include "mild_lcd/place/keyframe_map.hpp"
#include "mild_lcd/verification/candidate_verifier.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace mild {

// Where in a map a keyframe may find candidates: keyframes [0, eligible), less the near-past band
// when one is given. Another robot's map is all of it: its keyframes are never "a moment ago".
struct MapScope {
  KeyframeIndex eligible = kAllKeyframes;
  std::optional<NearPastRule> near_past;
};

// What one map answers for a keyframe (LoopDetector::queryMap): its similarity, the temporal
// filter's belief over it, and the best separated keyframes as candidates, not yet verified.
struct MapAnswer {
  QueryResult query;                      // Phi' against every keyframe in scope, and the query's stats
  std::vector<LoopCandidate> candidates;  // the filter's best, then the most similar, not yet verified
  double query_ms = 0.0;
  double filter_ms = 0.0;
};

// A map a keyframe is looked up in besides its detector's own (RobotTeam: another robot's), through
// a temporal filter of its own for this pair of maps.
struct OtherMap {
  const KeyframeMap* map = nullptr;
  TemporalFilter* filter = nullptr;
  uint32_t robot = 0;  // LoopCandidate::robot of its candidates
};

// Sorts candidates best first by probability (stable) and drops those below min_probability.
void rankCandidates(std::vector<LoopCandidate>& candidates, double min_probability);

// The keyframes a query reports, best first: belief above 0, ordered by belief, then similarity,
// then the older keyframe; each more than suppression_radius keyframes from every better one taken;
// at most max_count. Costs O(N) plus a sort of the few it looks at, not of all N keyframes.
std::vector<KeyframeIndex> separatedBest(const std::vector<double>& belief, const std::vector<double>& similarity,
                                         size_t max_count, KeyframeIndex suppression_radius);

// The loop-closure pipeline over a keyframe map (place/keyframe_map.hpp): a keyframe's features ->
// MIH query of the map (and of other robots' maps) -> Bayesian filter -> ranked candidates ->
// optional geometric verification and scoring -> the keyframe stored in the map. The detector owns
// its map; the pipeline's parts (scorer, verifier, the candidate parameters) are what retune
// changes. Images become features before they get here (detector/feature_front_end.hpp).
// Not thread-safe: callers serialise access.
// A keyframe stored with a best candidate of its own map at least this probable (and verified) is
// taken to show that candidate's place (KeyframeRecord::same_place_as): more likely than not.
constexpr double kSamePlaceProbability = 0.5;

// Whether keyframes a and b of `map` show one place: within `gap` keyframes of each other, or
// chained within it by what each was found to show when it was stored (KeyframeRecord::same_place_as).
bool samePlace(const KeyframeMap& map, KeyframeIndex a, KeyframeIndex b, KeyframeIndex gap);

class LoopDetector {
 public:
  explicit LoopDetector(const DetectorParams& params = {});
  ~LoopDetector();

  const DetectorParams& params() const { return params_; }

  // The map this detector's keyframes are stored in: read it, save it, load, merge or reset it.
  const KeyframeMap& map() const { return map_; }
  KeyframeMap& map() { return map_; }

  // Changes the parameters while running. Only runtimeParameterNames() may differ from params()
  // (detector/detector_parameters.hpp); anything else, or an invalid value, throws InvalidInput naming it and changes
  // nothing. A changed verification rebuilds the GeometricVerifier (a verifier installed with
  // setVerifier is kept). Touches only the candidate, scoring and verification parameters, so
  // a map's prepareRestore (which reads the database and filter ones) may run beside it.
  void retune(const DetectorParams& next);
  // How many retunes took effect: callers holding a copy of some parameters (a verifier of their
  // own) refresh it when this changes.
  uint64_t retunes() const { return retunes_; }

  // Replaces the check run on every reported candidate (a GeometricVerifier when
  // verification.enabled, none otherwise).
  void setVerifier(std::unique_ptr<CandidateVerifier> verifier) { verifier_ = std::move(verifier); }
  bool verifies() const { return verifier_ != nullptr; }

  // A map with no keyframe yet, of a detector whose width is its extractor's
  // (features/descriptor_bytes 0), takes another width (a front-end's own descriptors: ORB-SLAM's
  // 32 bytes, OKVIS's BRISK 64), so that such a front-end needs no setting whatever features/type
  // image input uses. Returns whether the map changed width. Throws InvalidInput, changing nothing,
  // when the parameters do not hold at that width (its bounds, the index's tables, the matcher's
  // substrings). Images extracted at another width are refused afterwards. Replaces the map
  // object: hold the lock its readers hold. RobotTeam::takeWidth does it for every robot at once.
  bool takeWidth(int bytes);

  // Processes one keyframe: its features (extracted by a FeatureFrontEnd, or computed elsewhere,
  // e.g. by the SLAM front-end), stamp and optional id. Their descriptors must have the map's width
  // (KeyframeMap::descriptorBytes()). Their camera is stored with the keyframe (it gives verified
  // loops a relative pose); their depths serve this query's verification only. Without an id, the
  // next free one (largest so far + 1) is used. observation.extract_ms is reported as
  // stats.extract_ms. Throws InvalidInput (and changes nothing) for an observation still holding an
  // image, mismatched keypoints and descriptors, another width, an id already in the map or above
  // kMaxKeyframeId, a non-finite stamp; CapacityError once no id is left to assign.
  // `others`: maps to look the keyframe up in besides this one (RobotTeam); their candidates are
  // verified, scored and ranked with this map's, and max_candidates bounds them all together.
  // `robot`: LoopCandidate::robot of this map's candidates and DetectionResult::query_robot.
  DetectionResult process(Observation observation, const std::vector<OtherMap>& others = {}, uint32_t robot = 0);

  // The one "query a map" step, for this detector's own keyframes and for another robot's map
  // (RobotTeam): `query` against `map`'s keyframes in `scope`, `filter`'s belief over them (it is
  // updated), and up to `max_candidates` of them, local maxima of the belief at least
  // suppression_radius apart, then the most similar. Changes neither map nor anything but `filter`.
  MapAnswer queryMap(const KeyframeMap& map, const DescriptorList& query, const MapScope& scope, TemporalFilter& filter,
                     size_t max_candidates) const;

  // The scorer's inputs of a candidate (CandidateScorer::Evidence).
  static CandidateScorer::Evidence evidenceOf(const LoopCandidate& c) {
    return {c.filter_probability, c.saliency, c.eligible_keyframes, c.other_place_significance};
  }
  const CandidateScorer& scorer() const { return scorer_; }

  // Verifies (when verifying) each candidate against the query, in the map it came from
  // (maps[i] for candidates[i]), then scores and judges it; ranks them (rankCandidates). Without
  // the query's features (nullptr) none is verified: each keeps its probability below the decision.
  void judge(std::vector<LoopCandidate>& candidates, const Features* query,
             const std::vector<const KeyframeMap*>& maps) const;
  // Whether candidate c could reach the decision probability if verified with `matches` matches
  // (all of them inliers): when false, verifying it (or fetching what that needs) changes no decision.
  bool couldBeAccepted(const LoopCandidate& c, int matches) const;

 private:
  // Throws InvalidInput, changing nothing, for features this map cannot take.
  void checkFeatures(const Features& features) const;
  // Where this detector's own keyframe at `stamp` may find candidates (exclusion, near-past band).
  MapScope ownScope(double stamp) const;
  // Which candidates are verified on purpose, whatever early stop would skip: the first
  // scoring/distinct_places of each map, in the order they were proposed.
  std::vector<bool> verifiedOnPurpose(const std::vector<const KeyframeMap*>& maps) const;
  // Candidate i's other_place_significance: the most significant of the candidates verified on
  // purpose (of those in `verifications`, the first verifications.size()) in its map and more than
  // scoring/distinct_place_gap keyframes from it.
  double otherPlaceSignificance(const std::vector<LoopCandidate>& candidates, size_t i,
                                const std::vector<const KeyframeMap*>& maps, const std::vector<bool>& on_purpose,
                                const std::vector<Verification>& verifications) const;
  // The probability candidate c is published with, given verification v: the scorer's, through the
  // verification gate (belowDecision) when v failed; the filter's when not verifying.
  double publishedProbability(const LoopCandidate& c, const Verification& v) const;
  // The highest probability candidate c can be published with after a fit of `matches` matches.
  double reachableProbability(const LoopCandidate& c, int matches) const;
  // Whether fitting candidate i (with `matches` descriptor matches) can change what is reported:
  // false when even `matches` inliers would leave it below the decision probability and below a
  // candidate already verified (verification/early_stop).
  bool fitCanMatter(const std::vector<LoopCandidate>& candidates, size_t i, int matches,
                    const std::vector<Verification>& earlier) const;

  DetectorParams params_;
  KeyframeMap map_;
  CandidateScorer scorer_;
  std::unique_ptr<CandidateVerifier> verifier_;
  uint64_t retunes_ = 0;
};

}  // namespace mild
