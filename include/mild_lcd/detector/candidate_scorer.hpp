#pragma once

// The loop probability a candidate is published with: the temporal filter's probability and the
// geometric verification's evidence, combined by a logistic model whose weights were fitted on
// sequences with ground truth (scripts/fit_scoring.py; README "Accuracy" says on which, and how
// it was cross-validated). Fitted by maximum likelihood, so that among candidates given probability
// p about a fraction p is right on sequences like the training ones: one threshold (0.5, "more
// likely a loop than not") for every scene, rather than a filter posterior whose scale depends on
// the scene.

#include <vector>

#include "mild_lcd/params/parameter_spec.hpp"
#include "mild_lcd/verification/candidate_verifier.hpp"

namespace mild {

struct ScoringParams {
  bool enabled = true;
  std::vector<double> weights = {0.501, -0.334, 3.475, 5.264, 9.630};
  double bias = -7.395;
  double decision_probability = 0.5;

  static constexpr int kFeatures = 5;
  static constexpr const char* kSection = "scoring";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("enabled", p.enabled, Bounds::any(),
      "The published loop probability: a logistic model of the filter's probability and the verification's "
      "evidence, x = [logit(filter probability), ln(inliers), inlier ratio, inlier coverage (share of the "
      "image's occupied 8 x 6 cells holding an inlier), homography share (share of the inliers one plane "
      "explains)]: p = 1 / (1 + exp(-(bias + weights . x))). Off gives the filter's probability as it is.");
    v("weights", p.weights, Bounds::list(kFeatures, kFeatures, Bounds::any()),
      "Fitted by scripts/fit_scoring.py on the sequences the README names (leave-one-kind-out cross-validated).");
    v("bias", p.bias, Bounds::any(), "The model's intercept.");
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

  // The features of one candidate, in the order of ScoringParams::weights.
  static std::vector<double> features(double filter_probability, const Verification& verification);
  // Unverified candidates (verification failed) get 0: they are not reported as loops.
  double probability(double filter_probability, const Verification& verification) const;

 private:
  ScoringParams params_;
};

}  // namespace mild
