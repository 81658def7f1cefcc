#pragma once

// The loop probability a candidate is published with: P(this candidate is a true loop), nothing
// else. The temporal filter's probability and the keyframe's own evidence -- its similarity's
// saliency among the query's eligible keyframes, and the geometric verification measured against
// chance (the a-contrario number of false alarms of its model, chance_agreement.hpp) -- combined by
// a logistic model fitted by plain maximum likelihood (every candidate weighing the same, right or
// wrong) on ORB runs of sequences with ground truth, rendered and real, at several keyframe steps
// (scripts/fit_scoring.py; docs/accuracy.md says on which, how it was cross-validated, and how it
// holds for BRISK and AKAZE, which it was not fitted on). Each input is scale-free: the saliency is a robust z against
// the query's own similarities, the significance divides out the matches, the tolerance and the image area, so that a
// count of inliers at 200 or 2,000 matches, 160 x 120 or 640 x 480, 256 or 512 bits is read on one scale. The filter's
// temporal reasoning enters as one term beside the keyframe's own evidence: a keyframe whose evidence is strong is not
// outvoted by a neighbour the filter's prior prefers but whose evidence is nil.
//
// What a wrong loop costs against a missed one is not in the probability: it is the decision
// (scoring/decision_probability, decisionForCost), so a back-end that weighs loops by their
// probability reads a probability, and one that acts on `accepted` gets the default's cost ratio.

#include <string>
#include <vector>

#include "mild_lcd/filter/temporal_filter.hpp"
#include "mild_lcd/params/parameter_spec.hpp"
#include "mild_lcd/verification/candidate_verifier.hpp"

namespace mild {

struct ScoringParams {
  bool enabled = true;
  std::vector<double> weights = {0.593, 0.804, 0.652, -0.733};
  double bias = -2.537;
  std::string filter_type = "exclusive_hypotheses";
  double decision_probability = 0.909;
  int min_comparable_keyframes = 5;
  int distinct_places = 3;
  int distinct_place_gap = 10;

  static constexpr int kFeatures = 4;
  static constexpr const char* kSection = "scoring";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("enabled", p.enabled, Bounds::any(),
      "The published loop probability of every candidate: a logistic model of the filter's probability and the "
      "keyframe's own evidence, x = [logit(filter probability) within +-4, ln(1 + significance), ln(max(1, "
      "saliency)), ln(1 + another place's significance)], "
      "significance being -log10 of the verified model's number of false alarms given the matches, the inlier "
      "tolerance and the image area (0 when chance explains it) and saliency the robust z of its similarity "
      "among the query's eligible keyframes, and another place's significance that of the most significant of "
      "the distinct places verified on purpose (distinct_places) more than distinct_place_gap keyframes away: p = 1 / "
      "(1 + exp(-(bias + weights . x))), fitted by maximum "
      "likelihood so that it is P(a true loop). A candidate that fails verification keeps its probability, "
      "capped just below decision_probability, and accepted is exactly probability >= decision_probability. Off "
      "(or verification off) gives the filter's probability as it is.");
    v("weights", p.weights, Bounds::list(kFeatures, kFeatures, Bounds::in(-1000, 1000)),
      "Fitted by scripts/fit_scoring.py on ORB runs of the sequences docs/accuracy.md names, real frames "
      "included, at keyframe steps 1, 2, 5 and 10; cross-validated leaving out whole kinds and whole steps, "
      "and measured unchanged on BRISK and AKAZE, which it was not fitted on (scripts/bench_calibration.sh).");
    v("bias", p.bias, Bounds::in(-1000, 1000), "The model's intercept.");
    v("filter_type", p.filter_type, Bounds::oneOf(temporalFilterTypes()),
      "The filter/type the weights were fitted with. The filter's probability is one of the model's inputs and "
      "another filter's means something else, so a configuration whose filter/type differs is refused (refit "
      "the weights with scripts/fit_scoring.py on that filter's runs, or turn scoring off).");
    v("decision_probability", p.decision_probability, Bounds::aboveUpTo(0, 1).runtime(),
      "Candidates at or above this probability are accepted (LoopCandidate.accepted). The cost of a wrong loop "
      "against a missed one belongs here, not in the probability: accepting is worth it when p >= c / (1 + c) "
      "for a wrong loop costing c missed ones; the default 0.909 is c = 10. With verification on, only "
      "verified candidates reach it.");
    v("min_comparable_keyframes", p.min_comparable_keyframes, Bounds::atLeast(0),
      "While a map has fewer eligible keyframes than this, the similarity's saliency and the filter's "
      "probability have nothing to compare a keyframe with: their terms take the values of no information "
      "(saliency 1, filter probability 0.5) and the probability rests on the geometry's significance: a loop at "
      "the first eligible keyframe is then the best candidate, more likely than not, and accepted once there "
      "are keyframes to compare it with. 0 = never.");
    v("distinct_places", p.distinct_places, Bounds::in(0, 64),
      "How many of a map's candidates, in the order they are proposed (the filter's best, then the most similar), "
      "are verified whatever verification/early_stop would skip: the places another place's significance is "
      "taken from.");
    v("distinct_place_gap", p.distinct_place_gap, Bounds::in(0, 1000000),
      "Keyframes between two candidates of one map for them to count as distinct places (another place's "
      "significance ignores the candidates within this many keyframes of the one scored).");
  }
  void validate() const;
};

class CandidateScorer {
 public:
  static constexpr int kFeatures = ScoringParams::kFeatures;
  explicit CandidateScorer(const ScoringParams& params);

  // What the scorer knows of a candidate besides its verification.
  struct Evidence {
    double filter_probability = 0.0;
    double saliency = 0.0;
    size_t eligible_keyframes = 0;  // of the map it was found in
    // The significance (-log10 NFA, at least 0) of the most significant other distinct place of the
    // same map verified on purpose: an aliased place verifies as well as the true one does, a
    // revisit of a place unlike the rest does not have a second place that verifies.
    double other_place_significance = 0.0;
  };
  // The features of one candidate, in the order of ScoringParams::weights, and their names (the
  // columns mild_offline --details writes for scripts/fit_scoring.py).
  std::vector<double> features(const Evidence& evidence, const Verification& verification) const;
  static const std::vector<std::string>& featureNames();
  // The calibrated probability of a candidate whose verification was attempted, verified or not
  // (the filter's probability when scoring is off); before the verification gate (belowDecision).
  double probability(const Evidence& evidence, const Verification& verification) const;

 private:
  ScoringParams params_;
};

// The verification gate: the probability a candidate that failed verification is published with,
// its own (calibrated like every other) but strictly below decision_probability, so that it is
// never accepted.
double belowDecision(double probability, double decision_probability);

// A verification's significance against chance, -log10 of its number of false alarms, at least 0
// (0 without a model).
double significanceOf(const Verification& verification);

// The decision probability for a wrong loop costing `wrong_loop_cost` missed ones: accepting is
// worth it when (1 - p) c < p, i.e. p >= c / (1 + c) (10 gives 0.909).
double decisionForCost(double wrong_loop_cost);

}  // namespace mild
