#pragma once

// The loop probability a candidate is published with: the temporal filter's probability and the
// geometric verification's evidence, combined by a logistic model whose weights were fitted on
// sequences with ground truth (scripts/fit_scoring.py; README "Accuracy" says on which, and how
// it was cross-validated). Fitted by maximum likelihood, so that among candidates given probability
// p about a fraction p is right on sequences like the training ones: one threshold (0.5, "more
// likely a loop than not") for every scene, rather than a filter posterior whose scale depends on
// the scene.

#include <vector>

#include "mild_lcd/verification/candidate_verifier.hpp"

namespace mild {

struct ScoringParams {
  // Off: the published probability is the filter's.
  bool enabled = true;
  // Weights of x = [logit(filter probability), ln(inliers), inlier ratio, inlier coverage,
  // homography share] and the bias: p = 1 / (1 + exp(-(bias + w . x))).
  std::vector<double> weights = {0.501, -0.334, 3.475, 5.264, 9.630};
  double bias = -7.395;
  // Candidates at or above this probability (and verified) are accepted: LoopCandidate.accepted.
  double decision_probability = 0.5;

  void validate() const;  // throws InvalidInput naming the first invalid field
};

class CandidateScorer {
 public:
  static constexpr int kFeatures = 5;
  explicit CandidateScorer(const ScoringParams& params);

  // The features of one candidate, in the order of ScoringParams::weights.
  static std::vector<double> features(double filter_probability, const Verification& verification);
  // Unverified candidates (verification failed) get 0: they are not reported as loops.
  double probability(double filter_probability, const Verification& verification) const;

 private:
  ScoringParams params_;
};

}  // namespace mild
