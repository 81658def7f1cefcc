#include "mild_lcd/detector/candidate_scorer.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

CandidateScorer::CandidateScorer(const ScoringParams& params) : params_((params.validate(), params)) {}

std::vector<double> CandidateScorer::features(const Evidence& e, const Verification& v) const {
  // Too few keyframes to compare with: the filter and the saliency are undecided.
  const bool comparable = e.eligible_keyframes >= static_cast<size_t>(params_.min_comparable_keyframes);
  const double p = comparable ? std::clamp(e.filter_probability, 1e-6, 1.0 - 1e-6) : 0.5;
  const double z = comparable && std::isfinite(e.saliency) ? std::max(1.0, e.saliency) : 1.0;
  return {std::log(p / (1.0 - p)), std::log(std::max(1, v.inliers)), std::log(z)};
}

const std::vector<std::string>& CandidateScorer::featureNames() {
  static const std::vector<std::string> names = {"x_filter_logodds", "x_ln_inliers", "x_ln_saliency"};
  return names;
}

double belowDecision(double probability, double decision_probability) {
  const double cap = std::min(decision_probability, 0.5);
  return std::min(std::clamp(probability, 0.0, 1.0) * cap, std::nextafter(cap, 0.0));
}

double CandidateScorer::probability(const Evidence& e, const Verification& v) const {
  if (!params_.enabled) return e.filter_probability;
  const std::vector<double> x = features(e, v);
  double z = params_.bias;
  for (int i = 0; i < kFeatures; ++i) z += params_.weights[i] * x[i];
  return 1.0 / (1.0 + std::exp(-z));
}

}  // namespace mild
