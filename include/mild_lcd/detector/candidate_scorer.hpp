#pragma once

// The loop probability a candidate is published with: the temporal filter's probability and the
// geometric verification's evidence, combined by a logistic model whose weights were fitted on
// sequences with ground truth, rendered and real (scripts/fit_scoring.py; docs/accuracy.md says on
// which, and how it was cross-validated). Only evidence that means the same on real camera frames
// as on the renders enters it: the inlier count of a wrong candidate (the chance agreement of
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
  std::vector<double> weights = {0.513, 1.048};
  double bias = -1.150;
  std::string filter_type = "exclusive_hypotheses";
  double decision_probability = 0.5;

  static constexpr int kFeatures = 2;
  static constexpr const char* kSection = "scoring";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("enabled", p.enabled, Bounds::any(),
      "The published loop probability of every candidate: a logistic model of the filter's probability and the "
      "verification's evidence, x = [logit(filter probability), ln(inliers)]: p = 1 / (1 + exp(-(bias + weights . "
      "x))). Candidates that fail verification keep a probability (low, from their few inliers) rather than 0, "
      "so that the probability ranks every candidate; only verified ones can be accepted. Off (or verification "
      "off) gives the filter's probability as it is.");
    v("weights", p.weights, Bounds::list(kFeatures, kFeatures, Bounds::any()),
      "Fitted by scripts/fit_scoring.py on the sequences docs/accuracy.md names, real frames included "
      "(leave-one-kind-out cross-validated).");
    v("bias", p.bias, Bounds::any(), "The model's intercept.");
    v("filter_type", p.filter_type, Bounds::oneOf(temporalFilterTypes()),
      "The filter/type the weights were fitted with. The filter's probability is one of the model's inputs and "
      "another filter's means something else, so a configuration whose filter/type differs is refused (refit "
      "the weights with scripts/fit_scoring.py on that filter's runs, or turn scoring off).");
    v("decision_probability", p.decision_probability, Bounds::aboveUpTo(0, 1).runtime(),
      "Verified candidates at or above this probability are accepted (LoopCandidate.accepted): \"more likely a "
      "loop than not\".");
  }
  void validate() const { validateDeclared(*this); }
};

class CandidateScorer {
 public:
  static constexpr int kFeatures = ScoringParams::kFeatures;
  explicit CandidateScorer(const ScoringParams& params);

  // The features of one candidate, in the order of ScoringParams::weights, and their names (the
  // columns mild_offline --details writes for scripts/fit_scoring.py).
  static std::vector<double> features(double filter_probability, const Verification& verification);
  static const std::vector<std::string>& featureNames();
  // The calibrated probability of a candidate whose verification was attempted, verified or not
  // (the filter's probability when scoring is off).
  double probability(double filter_probability, const Verification& verification) const;

 private:
  ScoringParams params_;
};

}  // namespace mild
