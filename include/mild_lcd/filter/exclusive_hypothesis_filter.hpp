#pragma once

#include <string>
#include <vector>

#include "mild_lcd/filter/temporal_filter.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

// The parameters of ExclusiveHypothesisFilter (below), section exclusive_hypotheses/. The names
// filter/<name> of earlier versions are read too (detector/detector_parameters.cpp).
struct ExclusiveHypothesisParams {
  double loop_persistence = 0.95;
  double loop_onset = 0.01;
  std::vector<double> motion_kernel = {0.3, 1.0, 0.6};
  double no_loop_likelihood = 10.0;
  double no_loop_growth = 0.5;
  double no_loop_reference_keyframes = 450.0;
  int candidate_window = 3;

  static constexpr const char* kSection = "exclusive_hypotheses";
  static constexpr const char* kDoc =
      "The temporal filter of filter/type exclusive_hypotheses (the default): one Bayesian filter over exclusive "
      "loop hypotheses (filter/exclusive_hypothesis_filter.hpp).";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("loop_persistence", p.loop_persistence, Bounds::probability(),
      "P(a loop continues from one keyframe to the next) (probability, 0 to 1).");
    v("loop_onset", p.loop_onset, Bounds::probability(),
      "P(a loop starts at this keyframe), spread evenly over the eligible keyframes (probability, 0 to 1).");
    v("motion_kernel", p.motion_kernel, Bounds::list(1, 64, Bounds::atLeast(0)),
      "Weights of the matched keyframe advancing 0, 1, 2, ... keyframes along the old trajectory per new keyframe "
      "(1 to 64 weights, each >= 0, at least one positive).");
    v("no_loop_likelihood", p.no_loop_likelihood, Bounds::above(0),
      "Likelihood of no loop at no_loop_reference_keyframes eligible keyframes (robust saliency z, > 0).");
    v("no_loop_growth", p.no_loop_growth, Bounds::in(0, 2),
      "Exponent of the no-loop likelihood's growth as (eligible keyframes / "
      "no_loop_reference_keyframes)^no_loop_growth, never below 1 (exponent, 0 = constant, up to 2).");
    v("no_loop_reference_keyframes", p.no_loop_reference_keyframes, Bounds::above(0),
      "Eligible keyframes at which the no-loop likelihood is no_loop_likelihood (keyframes, > 0).");
    v("candidate_window", p.candidate_window, Bounds::atLeast(0),
      "A candidate's filter probability is the posterior mass within this many keyframes of it (keyframes, >= 0).");
  }
  void validate() const;  // throws InvalidInput naming the first invalid field
};

// The likelihood of "no loop" with n eligible keyframes: no_loop_likelihood scaled by
// (n / no_loop_reference_keyframes)^no_loop_growth, and at least 1 (a keyframe's own likelihood is
// never below 1, so below it "no loop" could never win).
double noLoopLikelihood(const ExclusiveHypothesisParams& params, size_t eligible_keyframes);

// Bayesian filter over the similarity vector (seed paper III.A: "Bayesian inference employs
// temporal coherency to get a final probability of loop closure based on image similarity").
//
// State. For every eligible database keyframe j, p_j = P(the current keyframe closes a loop with
// j | all similarities so far), plus p_none = P(no loop). The hypotheses are exclusive (a keyframe
// is at one place at most), so for each keyframe j this is a two-state loop / no-loop filter whose
// "no loop with j" state is the mixture "loop with another keyframe, or no loop at all". That
// coupling is what makes a place that matches several stored places (perceptual aliasing: one
// facade material on many buildings) less probable than a place that matches one.
//
// Transition (temporal coherency). A robot that revisits a place keeps revisiting it, and the
// stored keyframe it matches moves forward along the old trajectory, about one keyframe per new
// keyframe. Belief at j therefore moves to j + d with weight motion_kernel[d] (normalised), it
// persists with probability loop_persistence, and a loop starts from "no loop" with probability
// loop_onset, spread evenly over the eligible keyframes:
//   prior_j    = persistence * sum_d K(d) p_{j-d}  +  onset * p_none / n
//   prior_none = (1 - persistence) * sum_j p_j     +  (1 - onset) * p_none
//
// Likelihood (saliency against the score distribution). The similarity vector s of the current
// keyframe is standardised robustly against its own distribution,
//   z_j = (s_j - median(s)) / (1.4826 * MAD(s)),
//   L_j = max(1, z_j),   L_none = noLoopLikelihood(params, n).
// Median and MAD, unlike mean and standard deviation, are not inflated by the matches themselves,
// so a strong match stays salient in a small map (a sample z-score cannot exceed sqrt(n) over n
// keyframes, which silenced loops in maps under ~100 keyframes). L_none is the saliency that "no
// loop" explains, and it grows with the number n of eligible keyframes: the largest z among n
// keyframes that show another place grows with n (measured on every kind of the bench, real
// frames included: about 3 at n = 50, 4-5 at 100-300, 8-13 at 500-1,000). A constant tuned on
// maps of many hundred keyframes (8) asked a loop in a map of 100 keyframes for twice the
// evidence it needs, and on real frames, whose loops reach z = 4-10 rather than the renders'
// 30-100, no loop ever won.
//
// Update: posterior proportional to likelihood x prior, normalised over all hypotheses.
//
// Reported loop probability of keyframe j: the posterior mass within +-candidate_window keyframes
// of j (neighbouring keyframes show the same place).
//
// Causal: the state after keyframe t depends only on similarities up to t; nothing published for a
// keyframe is revised later (the original MILD code rewrote loop flags up to three frames late).
class ExclusiveHypothesisFilter : public TemporalFilter {
 public:
  using Params = ExclusiveHypothesisParams;
  static constexpr const char* kName = "exclusive_hypotheses";
  explicit ExclusiveHypothesisFilter(const Params& params = {});
  const Params& params() const { return params_; }
  const char* name() const override { return kName; }

  // Returns the posterior mass within +-candidate_window of every eligible keyframe.
  const std::vector<double>& update(const std::vector<double>& similarity) override;

  const std::vector<double>& loopProbability() const override { return windowed_; }
  const std::vector<double>& posterior() const { return posterior_; }
  double noLoopProbability() const { return no_loop_; }
  size_t stateKeyframes() const override { return posterior_.size(); }
  void reset() override;
  // Replaces the state (non-negative, summing with no_loop to 1 within 1e-6).
  void setState(std::vector<double> posterior, double no_loop);
  std::vector<uint8_t> saveState() const override;
  void loadState(const std::vector<uint8_t>& bytes) override;
  size_t memoryBytes() const override;

 private:
  Params params_;
  std::vector<double> kernel_;  // motion_kernel normalised to sum 1
  std::vector<double> posterior_;
  double no_loop_ = 1.0;
  std::vector<double> prior_;
  std::vector<double> windowed_;
  std::vector<double> saliency_;
};

}  // namespace mild
