#pragma once

#include <vector>

#include "mild_lcd/filter/temporal_filter.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

// The parameters of IndependentBinaryFilter (below), section independent_binary/. The names
// filter/<name> of earlier versions are read too (detector/detector_parameters.cpp).
struct IndependentBinaryParams {
  double loop_persistence = 0.95;
  double no_loop_likelihood = 10.0;

  static constexpr const char* kSection = "independent_binary";
  static constexpr const char* kDoc =
      "The temporal filter of filter/type independent_binary: the 2017 MILD design, for comparison "
      "(filter/independent_binary_filter.hpp).";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("loop_persistence", p.loop_persistence, Bounds::probability(),
      "P(a keyframe's loop continues to the next keyframe) (probability, 0 to 1).");
    v("no_loop_likelihood", p.no_loop_likelihood, Bounds::above(0),
      "Likelihood of no loop against a keyframe's saliency (s - sigma) / mu (saliency units, > 0).");
  }
  void validate() const { validateDeclared(*this); }
};

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
  using Params = IndependentBinaryParams;
  static constexpr const char* kName = "independent_binary";
  explicit IndependentBinaryFilter(const Params& params = {});
  const char* name() const override { return kName; }

  const std::vector<double>& update(const std::vector<double>& similarity) override;
  const std::vector<double>& loopProbability() const override { return probability_; }
  size_t stateKeyframes() const override { return probability_.size(); }
  void reset() override { probability_.clear(); }
  std::vector<uint8_t> saveState() const override;
  void loadState(const std::vector<uint8_t>& bytes) override;
  size_t memoryBytes() const override { return (probability_.capacity() + previous_.capacity()) * sizeof(double); }

 private:
  Params params_;
  std::vector<double> probability_;
  std::vector<double> previous_;
};

}  // namespace mild
