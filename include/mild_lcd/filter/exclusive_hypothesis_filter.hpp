#pragma once

#include <vector>

#include "mild_lcd/filter/temporal_filter.hpp"

namespace mild {

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
  static constexpr const char* kName = "exclusive_hypotheses";
  explicit ExclusiveHypothesisFilter(const FilterParams& params = {});
  const FilterParams& params() const { return params_; }
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

 private:
  FilterParams params_;
  std::vector<double> kernel_;  // motion_kernel normalised to sum 1
  std::vector<double> posterior_;
  double no_loop_ = 1.0;
  std::vector<double> prior_;
  std::vector<double> windowed_;
  std::vector<double> saliency_;
};

}  // namespace mild
