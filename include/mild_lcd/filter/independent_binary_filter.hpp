#pragma once

#include <vector>

#include "mild_lcd/filter/temporal_filter.hpp"

namespace mild {

// The 2017 MILD design, kept to compare against (filter/type: independent_binary): every stored
// keyframe j has a two-state loop / no-loop filter of its own, independent of the others.
//
//   prior_j      = alpha_j * persistence + (1 - alpha_j) * (1 - persistence),
//                  alpha_j = the largest probability of keyframes j-2 .. j+2 at the previous step;
//   saliency_j   = (s_j - sigma) / mu, mu and sigma the mean and standard deviation of s;
//   L_j          = max(1, saliency_j), against no_loop_likelihood for "no loop";
//   p_j          = L_j prior_j / (L_j prior_j + no_loop_likelihood (1 - prior_j)).
//
// Without the coupling of ExclusiveHypothesisFilter, a place that looks like many stored places
// gives all of them a high probability (the original code then suppressed isolated flags by
// rewriting them up to three keyframes late; here nothing is rewritten).
class IndependentBinaryFilter : public TemporalFilter {
 public:
  static constexpr const char* kName = "independent_binary";
  explicit IndependentBinaryFilter(const FilterParams& params = {});
  const char* name() const override { return kName; }

  const std::vector<double>& update(const std::vector<double>& similarity) override;
  const std::vector<double>& loopProbability() const override { return probability_; }
  size_t stateKeyframes() const override { return probability_.size(); }
  void reset() override { probability_.clear(); }
  std::vector<uint8_t> saveState() const override;
  void loadState(const std::vector<uint8_t>& bytes) override;

 private:
  FilterParams params_;
  std::vector<double> probability_;
  std::vector<double> previous_;
};

}  // namespace mild
