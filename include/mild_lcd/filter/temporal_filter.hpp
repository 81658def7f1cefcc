#pragma once

// The temporal stage of the detector: it turns each keyframe's similarity vector into a loop
// probability per stored keyframe, using what earlier keyframes showed (temporal coherence). The
// detector owns one through this interface; which one is a parameter (filter/type), and the
// database file records it, so that a saved run is only resumed by the filter that wrote it.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

// The names filter/type accepts.
const std::vector<std::string>& temporalFilterTypes();

struct FilterParams {
  std::string type = "exclusive_hypotheses";
  double loop_persistence = 0.95;
  double loop_onset = 0.01;
  std::vector<double> motion_kernel = {0.3, 1.0, 0.6};
  double no_loop_likelihood = 10.0;
  double no_loop_growth = 0.5;
  double no_loop_reference_keyframes = 450.0;
  int candidate_window = 3;

  static constexpr const char* kSection = "filter";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("type", p.type, Bounds::oneOf(temporalFilterTypes()),
      "The temporal filter: exclusive_hypotheses (the default; filter/exclusive_hypothesis_filter.hpp) or "
      "independent_binary (the 2017 MILD design, for comparison). A saved run is only resumed by the filter type "
      "that wrote it.");
    v("loop_persistence", p.loop_persistence, Bounds::probability(),
      "P(a loop continues from one keyframe to the next).");
    v("loop_onset", p.loop_onset, Bounds::probability(),
      "P(a loop starts at this keyframe), spread evenly over the eligible keyframes.");
    v("motion_kernel", p.motion_kernel, Bounds::list(1, 64, Bounds::atLeast(0)),
      "Where the matched keyframe moves per new keyframe: weights of advancing 0, 1, 2, ... keyframes along the "
      "old trajectory (at least one positive). Revisits advance; aliasing tends to stay on one stored keyframe.");
    v("no_loop_likelihood", p.no_loop_likelihood, Bounds::above(0),
      "Likelihood of \"no loop\", in units of robust saliency (z), with no_loop_reference_keyframes eligible "
      "keyframes (see no_loop_growth).");
    v("no_loop_growth", p.no_loop_growth, Bounds::in(0, 2),
      "The no-loop likelihood grows as (eligible keyframes / no_loop_reference_keyframes)^no_loop_growth (never "
      "below 1): the largest saliency among keyframes of no loop grows with their number, from about 3 at 50 "
      "keyframes to 11-13 at 1,000 on every kind of the bench, real frames included (docs/accuracy.md). 0 = a "
      "constant no_loop_likelihood, the earlier design.");
    v("no_loop_reference_keyframes", p.no_loop_reference_keyframes, Bounds::above(0),
      "Eligible keyframes at which the no-loop likelihood is no_loop_likelihood.");
    v("candidate_window", p.candidate_window, Bounds::atLeast(0),
      "A candidate's loop probability is the posterior mass within +-candidate_window keyframes.");
  }
  void validate() const;  // throws InvalidInput naming the first invalid field
};

class TemporalFilter {
 public:
  virtual ~TemporalFilter() = default;

  // Recorded in database files; a saved state is only loaded into a filter of the same name.
  virtual const char* name() const = 0;

  // Advances one keyframe. similarity[j] is the current keyframe's similarity to eligible keyframe
  // j; the eligible set is a prefix of the database that may grow or shrink between calls (what
  // lies beyond a shorter prefix is forgotten). Returns the loop probability of every eligible
  // keyframe. Causal: nothing returned for an earlier keyframe is ever revised.
  virtual const std::vector<double>& update(const std::vector<double>& similarity) = 0;
  virtual const std::vector<double>& loopProbability() const = 0;
  // How many keyframes the state covers (the eligible prefix of the last update).
  virtual size_t stateKeyframes() const = 0;
  virtual void reset() = 0;

  // The state as bytes and back, bit-exact (a resumed run continues exactly). loadState throws
  // InvalidInput, changing nothing, for bytes that are not a state of this filter.
  virtual std::vector<uint8_t> saveState() const = 0;
  virtual void loadState(const std::vector<uint8_t>& bytes) = 0;
};

// The likelihood of "no loop" with n eligible keyframes: no_loop_likelihood scaled by
// (n / no_loop_reference_keyframes)^no_loop_growth, and at least 1 (a keyframe's own likelihood is
// never below 1, so below it "no loop" could never win).
double noLoopLikelihood(const FilterParams& params, size_t eligible_keyframes);

// The filter params.type names; throws InvalidInput for an unknown type.
std::unique_ptr<TemporalFilter> makeTemporalFilter(const FilterParams& params);

// Robust standardisation of a similarity vector: (s - median) / (1.4826 MAD), falling back to the
// mean absolute deviation from the median when more than half the values are equal, and to all
// zeros when every value is equal.
std::vector<double> robustSaliency(const std::vector<double>& similarity);

}  // namespace mild
