#pragma once

// The loop probability a candidate is published with: the temporal filter's probability, the
// keyframe's own evidence (its similarity's saliency among the query's eligible keyframes, and the
// geometric verification's inliers), combined by a logistic model whose weights were fitted on
// sequences with ground truth, rendered and real, at several keyframe steps (scripts/fit_scoring.py;
// docs/accuracy.md says on which, and how it was cross-validated). The filter's temporal reasoning
// enters as one term beside the keyframe's own evidence: a keyframe whose evidence is strong is not
// outvoted by a neighbour the filter's prior prefers but whose evidence is nil. Only evidence that means the same on
// real camera frames as on the renders enters it: the inlier count of a wrong candidate (the chance agreement of
// matches with a fundamental matrix) is 11-12 at the median on both, while the inlier ratio, the
// inlier coverage and the share one plane explains differ between a world of planar walls and a
// real one (docs/accuracy.md measures each). Fitted by maximum likelihood, so that among candidates given probability
// p about a fraction p is right on sequences like the training ones: one threshold (0.5, "more
// likely a loop than not") for every scene, rather than a filter posterior whose scale depends on
// the scene.

#include <string>
#include <vector>

#include "mild_lcd/filter/temporal_filter.hpp"
#include "mild_lcd/params/parameter_spec.hpp"
#include "mild_lcd/verification/candidate_verifier.hpp"

namespace mild {

struct ScoringParams {
  bool enabled = true;
  std::vector<double> weights = {0.398, 1.728, 0.230};
  double bias = -7.737;
  std::string filter_type = "exclusive_hypotheses";
  double decision_probability = 0.5;
  int min_comparable_keyframes = 5;

  static constexpr int kFeatures = 3;
  static constexpr const char* kSection = "scoring";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("enabled", p.enabled, Bounds::any(),
      "The published loop probability of every candidate: a logistic model of the filter's probability and the "
      "keyframe's own evidence, x = [logit(filter probability), ln(inliers), ln(max(1, saliency))], saliency "
      "being the robust z of its similarity among the query's eligible keyframes: p = 1 / (1 + exp(-(bias + "
      "weights . x))). A candidate that fails verification is published below decision_probability (and below "
      "0.5): its probability scaled by the lower of the two, so that it still ranks among the unverified ones, "
      "and accepted is exactly probability >= decision_probability. Off (or verification off) gives the "
      "filter's probability as it is.");
    v("weights", p.weights, Bounds::list(kFeatures, kFeatures, Bounds::any()),
      "Fitted by scripts/fit_scoring.py on the sequences docs/accuracy.md names, real frames included, at "
      "keyframe steps 1, 2, 5 and 10 (cross-validated leaving out whole kinds and whole steps).");
    v("bias", p.bias, Bounds::any(), "The model's intercept.");
    v("filter_type", p.filter_type, Bounds::oneOf(temporalFilterTypes()),
      "The filter/type the weights were fitted with. The filter's probability is one of the model's inputs and "
      "another filter's means something else, so a configuration whose filter/type differs is refused (refit "
      "the weights with scripts/fit_scoring.py on that filter's runs, or turn scoring off).");
    v("decision_probability", p.decision_probability, Bounds::aboveUpTo(0, 1).runtime(),
      "Candidates at or above this probability are accepted (LoopCandidate.accepted): \"more likely a loop than "
      "not\". With verification on, only verified candidates reach it.");
    v("min_comparable_keyframes", p.min_comparable_keyframes, Bounds::atLeast(0),
      "While a map has fewer eligible keyframes than this, the similarity's saliency and the filter's "
      "probability have nothing to compare a keyframe with: their terms take the values of no information "
      "(saliency 1, filter probability 0.5) and the probability rests on the inliers. A loop at the first "
      "eligible keyframe is then accepted on its geometry. 0 = never.");
  }
  void validate() const { validateDeclared(*this); }
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
// `probability` scaled by min(decision_probability, 0.5) and strictly below it, so that it is never
// accepted and never reads as "more likely than not", while keeping its order among the unverified.
double belowDecision(double probability, double decision_probability);

}  // namespace mild
