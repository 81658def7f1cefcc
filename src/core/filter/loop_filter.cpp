#include "mild_lcd/filter/loop_filter.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

void FilterParams::validate() const {
  auto probability = [](double v, const char* name) {
    if (!(v >= 0.0 && v <= 1.0)) throw InvalidInput(std::string(name) + " must be a probability in [0, 1], got " + std::to_string(v));
  };
  probability(loop_persistence, "filter/loop_persistence");
  probability(loop_onset, "filter/loop_onset");
  if (motion_kernel.empty() || motion_kernel.size() > 64) {
    throw InvalidInput("filter/motion_kernel must list 1 to 64 weights (advancing 0, 1, 2, ... keyframes)");
  }
  double total = 0.0;
  for (double w : motion_kernel) {
    if (!(w >= 0.0) || !std::isfinite(w)) throw InvalidInput("filter/motion_kernel weights must be >= 0");
    total += w;
  }
  if (!(total > 0.0)) throw InvalidInput("filter/motion_kernel needs at least one positive weight");
  if (!(no_loop_likelihood > 0.0) || !std::isfinite(no_loop_likelihood)) {
    throw InvalidInput("filter/no_loop_likelihood must be a positive number, got " + std::to_string(no_loop_likelihood));
  }
  if (candidate_window < 0) throw InvalidInput("filter/candidate_window must be >= 0, got " + std::to_string(candidate_window));
}

namespace {

// Median with the two middle values averaged for an even count; reorders its argument.
double median(std::vector<double>& v) {
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(mid), v.end());
  const double upper = v[mid];
  if (v.size() % 2 == 1) return upper;
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + static_cast<long>(mid)));
}

}  // namespace

std::vector<double> robustSaliency(const std::vector<double>& similarity) {
  std::vector<double> z(similarity.size(), 0.0);
  if (similarity.empty()) return z;
  std::vector<double> work = similarity;
  const double centre = median(work);
  double mean_abs = 0.0;
  for (size_t j = 0; j < similarity.size(); ++j) {
    work[j] = std::abs(similarity[j] - centre);
    mean_abs += work[j];
  }
  mean_abs /= static_cast<double>(similarity.size());
  double scale = 1.4826 * median(work);  // consistent with the standard deviation of a normal
  if (!(scale > 0.0)) scale = 1.2533 * mean_abs;
  if (!(scale > 0.0) || !std::isfinite(scale)) return z;
  for (size_t j = 0; j < similarity.size(); ++j) z[j] = (similarity[j] - centre) / scale;
  return z;
}

LoopFilter::LoopFilter(const FilterParams& params) : params_((params.validate(), params)) {
  const double total = std::accumulate(params_.motion_kernel.begin(), params_.motion_kernel.end(), 0.0);
  for (double w : params_.motion_kernel) kernel_.push_back(w / total);
}

void LoopFilter::reset() {
  posterior_.clear();
  windowed_.clear();
  no_loop_ = 1.0;
}

void LoopFilter::setState(std::vector<double> posterior, double no_loop) {
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

const std::vector<double>& LoopFilter::update(const std::vector<double>& similarity) {
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
  double total = params_.no_loop_likelihood * prior_none;
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
  no_loop_ = params_.no_loop_likelihood * prior_none / total;

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

}  // namespace mild
