#include "mild_lcd/detector/candidate_scorer.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

namespace {
const double kFilterFloor = 1.0 / (1.0 + std::exp(4.0));
}  // namespace

CandidateScorer::CandidateScorer(const ScoringParams& params) : params_((params.validate(), params)) {}

std::vector<double> CandidateScorer::features(const Evidence& e, const Verification& v) const {
  // Too few keyframes to compare with: the filter and the saliency are undecided.
  const bool comparable = e.eligible_keyframes >= static_cast<size_t>(params_.min_comparable_keyframes);
  // The filter's log-odds bounded to +-4 (p in [0.018, 0.982]): its prior may add to a keyframe's own
  // evidence or take from it, never outvote it (a filter sure of a neighbour, at 1e-6 for this
  // keyframe, would otherwise cancel a verified revisit; bounded, the kind-left-out fit ranks better).
  const double p = comparable ? std::clamp(e.filter_probability, kFilterFloor, 1.0 - kFilterFloor) : 0.5;
  const double z = comparable && std::isfinite(e.saliency) ? std::max(1.0, e.saliency) : 1.0;
  // The geometry's evidence against chance, scale-free (chance_agreement.hpp); its logarithm, because
  // past a few orders of magnitude more significance says little more about a loop (an aliased
  // place gives a model as significant as the true one).
  // Another distinct place that verifies too says the scene repeats itself (the same furniture in
  // two rooms, identical doors): the fitted weight is at most 0, so it can only lower the probability.
  const double other = std::isfinite(e.other_place_significance) ? std::max(0.0, e.other_place_significance) : 0.0;
  return {std::log(p / (1.0 - p)), std::log1p(significanceOf(v)), std::log(z), std::log1p(other)};
}

const std::vector<std::string>& CandidateScorer::featureNames() {
  static const std::vector<std::string> names = {"x_filter_logodds", "x_ln_significance", "x_ln_saliency",
                                                 "x_ln_other_place_significance"};
  return names;
}

void ScoringParams::validate() const {
  validateDeclared(*this);
  // Early stop bounds a candidate's probability from above with another place's significance as
  // known so far (none yet = 0): that holds only while more of it can never raise the probability.
  if (weights.size() == static_cast<size_t>(kFeatures) && weights[3] > 0.0) {
    throw InvalidInput("scoring/weights[3] (another place's significance) must be at most 0, got " +
                       std::to_string(weights[3]));
  }
}

double significanceOf(const Verification& v) {
  return std::isfinite(v.log10_false_alarms) ? std::max(0.0, -v.log10_false_alarms) : 0.0;
}

double belowDecision(double probability, double decision_probability) {
  return std::min(std::clamp(probability, 0.0, 1.0), std::nextafter(decision_probability, 0.0));
}

double decisionForCost(double wrong_loop_cost) {
  // Accept when the expected cost of accepting, (1 - p) c, is below that of missing, p.
  return wrong_loop_cost / (1.0 + wrong_loop_cost);
}

double CandidateScorer::probability(const Evidence& e, const Verification& v) const {
  if (!params_.enabled) return e.filter_probability;
  const std::vector<double> x = features(e, v);
  double z = params_.bias;
  for (int i = 0; i < kFeatures; ++i) z += params_.weights[i] * x[i];
  // Bounded weights and inputs keep z finite; should it not be, no evidence beats the filter's own
  // probability (a NaN would sort candidates undefinedly and be published).
  if (!std::isfinite(z)) return e.filter_probability;
  return 1.0 / (1.0 + std::exp(-z));
}

}  // namespace mild
