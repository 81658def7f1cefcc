#include "mild_lcd/filter/exclusive_hypothesis_filter.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/filter/filter_state.hpp"

namespace mild {

void ExclusiveHypothesisParams::validate() const {
  validateDeclared(*this);
  double total = 0.0;
  for (double w : motion_kernel) total += w;
  if (!(total > 0.0)) throw InvalidInput(std::string(kSection) + "/motion_kernel needs at least one positive weight");
}

double noLoopLikelihood(const ExclusiveHypothesisParams& params, size_t eligible_keyframes) {
  if (params.no_loop_growth == 0.0) return params.no_loop_likelihood;
  const double ratio = static_cast<double>(eligible_keyframes) / params.no_loop_reference_keyframes;
  return std::max(1.0, params.no_loop_likelihood * std::pow(ratio, params.no_loop_growth));
}

ExclusiveHypothesisFilter::ExclusiveHypothesisFilter(const Params& params) : params_((params.validate(), params)) {
  const double total = std::accumulate(params_.motion_kernel.begin(), params_.motion_kernel.end(), 0.0);
  for (double w : params_.motion_kernel) kernel_.push_back(w / total);
}

void ExclusiveHypothesisFilter::reset() {
  posterior_.clear();
  windowed_.clear();
  no_loop_ = 1.0;
}

void ExclusiveHypothesisFilter::setState(std::vector<double> posterior, double no_loop) {
  double total = no_loop;
  for (double p : posterior) {
    if (!(p >= 0.0) || !std::isfinite(p)) throw InvalidInput("filter state must hold non-negative probabilities");
    total += p;
  }
  if (!(no_loop >= 0.0) || std::abs(total - 1.0) > 1e-6) throw InvalidInput("filter state must sum to 1");
  posterior_ = std::move(posterior);
  no_loop_ = no_loop;
  windowed_.clear();
}

// Layout: u32 count, count doubles (the posterior), one double (no loop). Native byte order, as the
// rest of the database file.
std::vector<uint8_t> ExclusiveHypothesisFilter::saveState() const { return packFilterState(posterior_, {no_loop_}); }

void ExclusiveHypothesisFilter::loadState(const std::vector<uint8_t>& bytes) {
  FilterStateValues state = unpackFilterState(bytes, 1);
  setState(std::move(state.values), state.extra.front());
}

const std::vector<double>& ExclusiveHypothesisFilter::update(const std::vector<double>& similarity) {
  const size_t n = similarity.size();
  if (n < posterior_.size()) {  // the database was cut: what was beyond it is "no loop" now
    for (size_t j = n; j < posterior_.size(); ++j) no_loop_ += posterior_[j];
    posterior_.resize(n);
  }
  windowed_.assign(n, 0.0);
  if (n == 0) return windowed_;

  // Prediction.
  const double persistence = params_.loop_persistence;
  const double onset = params_.loop_onset;
  const size_t previous = posterior_.size();
  double previous_loop_mass = 0.0;
  for (double p : posterior_) previous_loop_mass += p;
  prior_.assign(n, onset * no_loop_ / static_cast<double>(n));
  for (size_t j = 0; j < previous; ++j) {
    const double moving = persistence * posterior_[j];
    if (moving == 0.0) continue;
    for (size_t d = 0; d < kernel_.size() && j + d < n; ++d) prior_[j + d] += kernel_[d] * moving;
  }
  const double prior_none = (1.0 - persistence) * previous_loop_mass + (1.0 - onset) * no_loop_;

  // Likelihood from saliency.
  saliency_ = robustSaliency(similarity);
  posterior_.resize(n);
  const double no_loop_likelihood = noLoopLikelihood(params_, n);
  double total = no_loop_likelihood * prior_none;
  for (size_t j = 0; j < n; ++j) {
    const double likelihood = std::isfinite(saliency_[j]) ? std::max(1.0, saliency_[j]) : 1.0;
    posterior_[j] = likelihood * prior_[j];
    total += posterior_[j];
  }
  if (!(total > 0.0) || !std::isfinite(total)) {  // nothing left to normalise: restart from "no loop"
    std::fill(posterior_.begin(), posterior_.end(), 0.0);
    no_loop_ = 1.0;
    return windowed_;
  }
  for (double& p : posterior_) p /= total;
  no_loop_ = no_loop_likelihood * prior_none / total;

  // Loop probability per keyframe: posterior mass of its neighbourhood (a running window sum).
  const size_t w = static_cast<size_t>(params_.candidate_window);
  double running = 0.0;
  for (size_t j = 0; j < std::min(n, w); ++j) running += posterior_[j];
  for (size_t j = 0; j < n; ++j) {
    if (j + w < n) running += posterior_[j + w];
    if (j > w) running -= posterior_[j - w - 1];
    windowed_[j] = std::min(1.0, std::max(0.0, running));
  }
  return windowed_;
}

size_t ExclusiveHypothesisFilter::memoryBytes() const {
  return (kernel_.capacity() + posterior_.capacity() + prior_.capacity() + windowed_.capacity() +
          saliency_.capacity()) *
         sizeof(double);
}

}  // namespace mild
