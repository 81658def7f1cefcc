#include "mild_lcd/detector/candidate_scorer.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

CandidateScorer::CandidateScorer(const ScoringParams& params) : params_((params.validate(), params)) {}

std::vector<double> CandidateScorer::features(double filter_probability, const Verification& v) {
  const double p = std::clamp(filter_probability, 1e-6, 1.0 - 1e-6);
  return {std::log(p / (1.0 - p)), std::log(std::max(1, v.inliers))};
}

const std::vector<std::string>& CandidateScorer::featureNames() {
  static const std::vector<std::string> names = {"x_filter_logodds", "x_ln_inliers"};
  return names;
}

double CandidateScorer::probability(double filter_probability, const Verification& v) const {
  if (!params_.enabled) return filter_probability;
  const std::vector<double> x = features(filter_probability, v);
  double z = params_.bias;
  for (int i = 0; i < kFeatures; ++i) z += params_.weights[i] * x[i];
  return 1.0 / (1.0 + std::exp(-z));
}

}  // namespace mild
