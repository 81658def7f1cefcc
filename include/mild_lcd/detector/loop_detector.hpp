#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/detector/candidate_scorer.hpp"
#include "mild_lcd/detector/observation.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/filter/filters.hpp"
#include "mild_lcd/params/parameter_spec.hpp"
#include "mild_lcd/place/keyframe_database.hpp"
#include "mild_lcd/place/keyframe_map.hpp"
#include "mild_lcd/verification/candidate_verifier.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace mild {

struct CandidateParams {
  int exclusion_frames = 40;
  double exclusion_seconds = 0.0;
  bool near_past = true;
  double near_past_rise = 3.0;
  int max_candidates = 3;
  int similarity_candidates = 2;
  int suppression_radius = 5;
  double min_probability = 0.0;
  int other_maps_per_keyframe = 1;

  static constexpr const char* kSection = "detector";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("exclusion_frames", p.exclusion_frames, Bounds::atLeast(0).runtime(),
      "Temporal exclusion: keyframes fewer than exclusion_frames keyframes before the query are never candidates "
      "and take no part in the similarity (they trivially look alike). 40 = the bench's evaluation gap (the "
      "original code used 60).");
    v("exclusion_seconds", p.exclusion_seconds, Bounds::atLeast(0).runtime(),
      "When > 0, also those fewer than this many seconds before the query.");
    v("near_past", p.near_past, Bounds::any(),
      "The near-past band: beyond the exclusion, the newest keyframes whose view is still continuous with the "
      "query's (far buildings seen while walking towards them, a slow camera at a high keyframe rate) are "
      "excluded too. Walking back from the newest eligible keyframe, the band goes on while the number of query "
      "features matched in the keyframe does not rise out of the valley, the fewest matched in any keyframe "
      "between it and the query (the exclusion window included): a revisit is separated from the present by "
      "keyframes that show neither place. No background and no warm-up: a revisit at the first eligible "
      "keyframe is a candidate at once (place/near_past.hpp).");
    v("near_past_rise", p.near_past_rise, Bounds::in(0, 10),
      "How far a keyframe's matched count must rise above the valley to end the band, in units of the "
      "valley's square root (the spread of a count). Chosen by cross-validation over kinds and keyframe steps "
      "(docs/accuracy.md).");
    v("max_candidates", p.max_candidates, Bounds::in(1, 100).runtime(),
      "Up to this many candidates per keyframe are reported, best first by their published probability (each is "
      "verified: the bound keeps a keyframe's work bounded).");
    v("similarity_candidates", p.similarity_candidates, Bounds::in(0, 100).runtime(),
      "Besides the max_candidates best keyframes of the temporal filter, this many of the most similar "
      "keyframes are verified and scored too (local maxima at least suppression_radius apart), so that a "
      "keyframe with strong evidence is judged on it even when the filter's belief sits elsewhere. The best "
      "max_candidates of both are reported.");
    v("suppression_radius", p.suppression_radius, Bounds::atLeast(0).runtime(),
      "Candidates of one kind (the filter's, the similarity's) are local maxima at least this many keyframes "
      "apart.");
    v("min_probability", p.min_probability, Bounds::probability().runtime(),
      "Candidates below this (calibrated) loop probability are not reported. 0 reports every keyframe's best "
      "candidates, which precision-recall evaluation needs; for a hard decision use LoopCandidate.accepted "
      "(scoring/decision_probability).");
    v("other_maps_per_keyframe", p.other_maps_per_keyframe, Bounds::atLeast(1).orZero(),
      "Several robots (RobotTeam): each keyframe is looked up in its robot's own map and in this many of the other "
      "robots' maps, taken in turn (0 = every map), so that with R robots each other map is asked every "
      "(R - 1) / other_maps_per_keyframe keyframes and the work per keyframe stays that of 1 + "
      "other_maps_per_keyframe queries however large the team. A revisit lasts many keyframes: it is still found, "
      "a few keyframes later. With two robots 1 asks every map. docs/multi_robot.md measures both.");
  }
  void validate() const { validateDeclared(*this); }
};

struct DetectorParams {
  FeatureParams features;
  // database.descriptor_bytes is not read: the detector's database takes its width from `features`.
  DatabaseParams database;
  FilterParams filter;
  CandidateParams candidates;
  VerificationParams verification;
  ScoringParams scoring;
  SearchMode search = SearchMode::kIndex;

  // The database parameters the detector runs with: `database` at the features' width.
  DatabaseParams databaseParams() const;
  void validate() const;
};

struct LoopCandidate {
  uint64_t id = 0;          // the candidate keyframe's id
  uint32_t session = 0;     // and its session
  uint32_t robot = 0;       // and the robot whose map holds it (RobotTeam; 0 for a lone detector)
  KeyframeIndex index = 0;  // its position in the database
  double stamp = 0.0;
  double probability = 0.0;         // calibrated loop probability (CandidateScorer)
  double filter_probability = 0.0;  // the temporal filter's probability, one of its inputs
  double similarity = 0.0;          // Phi' of the query against this keyframe
  double saliency = 0.0;            // its robust z among the query's eligible keyframes (robustSaliency)
  size_t eligible_keyframes = 0;    // how many keyframes of its map were eligible (and compared)
  // The significance of the most significant other distinct place of its map verified on purpose
  // (CandidateScorer::Evidence::other_place_significance).
  double other_place_significance = 0.0;
  bool accepted = false;            // probability >= scoring/decision_probability (so verified, when verifying)
  Verification verification;        // geometric check (verified=false, inliers=0 when verification is off)
};

struct StepStats {
  double extract_ms = 0.0;
  double query_ms = 0.0;
  double filter_ms = 0.0;
  double verify_ms = 0.0;
  size_t features = 0;
  size_t eligible_keyframes = 0;
  size_t near_past_keyframes = 0;  // removed from the eligible ones by the near-past band
  // The keyframe's stamp was below the previous one's of the running session: its clock stepped
  // back, counted as no time passing (SessionClock).
  bool clock_stepped_back = false;
  // Its depths that were given but are not plausible (finite, not 0, outside [kMinDepthMetres,
  // kMaxDepthMetres]): taken as unknown (features/features.hpp).
  size_t depths_out_of_range = 0;
  QueryStats query;
};

struct DetectionResult {
  uint64_t query_id = 0;
  uint32_t query_session = 0;
  uint32_t query_robot = 0;  // RobotTeam: the robot that saw the query
  KeyframeIndex query_index = 0;
  std::vector<LoopCandidate> candidates;  // best first
  // The candidates that were verified and scored but fell beyond max_candidates, best first: not
  // reported, kept for evaluation (mild_offline --fit-every-candidate writes them as training data).
  std::vector<LoopCandidate> unreported;
  std::vector<double> similarity;  // Phi' against every eligible keyframe (by database index)
  StepStats stats;
};

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
