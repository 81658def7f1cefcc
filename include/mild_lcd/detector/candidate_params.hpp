#pragma once

// How a keyframe's candidates are chosen and reported (the detector/ section of the parameters).

#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

struct CandidateParams {
  int exclusion_frames = 40;
  double exclusion_seconds = 0.0;
  bool near_past = true;
  double near_past_rise = 4.0;
  int max_candidates = 3;
  int similarity_candidates = 2;
  int suppression_radius = 5;
  double min_probability = 0.0;
  int other_maps_per_keyframe = 1;

  static constexpr const char* kSection = "detector";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("exclusion_frames", p.exclusion_frames, Bounds::atLeast(0).runtime(),
      "Keyframes fewer than this many before the query are never candidates and take no part in the similarity "
      "(keyframes, >= 0).");
    v("exclusion_seconds", p.exclusion_seconds, Bounds::atLeast(0).runtime(),
      "Keyframes fewer than this many seconds before the query are excluded too (seconds, >= 0; 0 = off).");
    v("near_past", p.near_past, Bounds::any(),
      "Whether the newest eligible keyframes whose view is still continuous with the query's, walking back while "
      "their matched-feature count stays in its valley, are excluded too (true or false; place/near_past.hpp).");
    v("near_past_rise", p.near_past_rise, Bounds::in(0, 10),
      "Rise of a keyframe's matched-feature count above the valley that ends the near-past band (square roots of "
      "the valley's count, 0 to 10).");
    v("max_candidates", p.max_candidates, Bounds::in(1, 100).runtime(),
      "Candidates reported per keyframe, best first by probability, each verified (candidates, 1 to 100).");
    v("similarity_candidates", p.similarity_candidates, Bounds::in(0, 100).runtime(),
      "Most similar keyframes verified and scored besides the filter's max_candidates best, local maxima "
      "suppression_radius apart (keyframes, 0 to 100).");
    v("suppression_radius", p.suppression_radius, Bounds::atLeast(0).runtime(),
      "Candidates of one kind (the filter's, the similarity's) are local maxima at least this far apart "
      "(keyframes, >= 0).");
    v("min_probability", p.min_probability, Bounds::probability().runtime(),
      "Candidates below this loop probability are not reported; 0 reports every keyframe's best, as evaluation "
      "needs (probability, 0 to 1).");
    v("other_maps_per_keyframe", p.other_maps_per_keyframe, Bounds::atLeast(1).orZero(),
      "Other robots' maps each keyframe is looked up in besides its own, taken in turn (maps, 0 = every map, else "
      ">= 1).");
  }
  void validate() const { validateDeclared(*this); }
};

}  // namespace mild
