#pragma once

// How a keyframe's candidates are chosen and reported (the detector/ section of the parameters).

#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

struct CandidateParams {
  int exclusion_frames = 40;
  double exclusion_seconds = 0.0;
  bool near_past = true;
  double near_past_rise = 3.0;
  int max_candidates = 3;
  int similarity_candidates = 2;
  int suppression_radius = 5;
  double min_probability = 0.0;
  int other_maps_per_keyframe = 1;

  static constexpr const char* kSection = "detector";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("exclusion_frames", p.exclusion_frames, Bounds::atLeast(0).runtime(),
      "Temporal exclusion: keyframes fewer than exclusion_frames keyframes before the query are never candidates "
      "and take no part in the similarity (they trivially look alike). 40 = the bench's evaluation gap (the "
      "original code used 60).");
    v("exclusion_seconds", p.exclusion_seconds, Bounds::atLeast(0).runtime(),
      "When > 0, also those fewer than this many seconds before the query.");
    v("near_past", p.near_past, Bounds::any(),
      "The near-past band: beyond the exclusion, the newest keyframes whose view is still continuous with the "
      "query's (far buildings seen while walking towards them, a slow camera at a high keyframe rate) are "
      "excluded too. Walking back from the newest eligible keyframe, the band goes on while the number of query "
      "features matched in the keyframe does not rise out of the valley, the fewest matched in any keyframe "
      "between it and the query (the exclusion window included): a revisit is separated from the present by "
      "keyframes that show neither place. No background and no warm-up: a revisit at the first eligible "
      "keyframe is a candidate at once (place/near_past.hpp).");
    v("near_past_rise", p.near_past_rise, Bounds::in(0, 10),
      "How far a keyframe's matched count must rise above the valley to end the band, in units of the "
      "valley's square root (the spread of a count). Chosen by cross-validation over kinds and keyframe steps "
      "(docs/accuracy.md).");
    v("max_candidates", p.max_candidates, Bounds::in(1, 100).runtime(),
      "Up to this many candidates per keyframe are reported, best first by their published probability (each is "
      "verified: the bound keeps a keyframe's work bounded).");
    v("similarity_candidates", p.similarity_candidates, Bounds::in(0, 100).runtime(),
      "Besides the max_candidates best keyframes of the temporal filter, this many of the most similar "
      "keyframes are verified and scored too (local maxima at least suppression_radius apart), so that a "
      "keyframe with strong evidence is judged on it even when the filter's belief sits elsewhere. The best "
      "max_candidates of both are reported.");
    v("suppression_radius", p.suppression_radius, Bounds::atLeast(0).runtime(),
      "Candidates of one kind (the filter's, the similarity's) are local maxima at least this many keyframes "
      "apart.");
    v("min_probability", p.min_probability, Bounds::probability().runtime(),
      "Candidates below this (calibrated) loop probability are not reported. 0 reports every keyframe's best "
      "candidates, which precision-recall evaluation needs; for a hard decision use LoopCandidate.accepted "
      "(scoring/decision_probability).");
    v("other_maps_per_keyframe", p.other_maps_per_keyframe, Bounds::atLeast(1).orZero(),
      "Several robots (RobotTeam): each keyframe is looked up in its robot's own map and in this many of the other "
      "robots' maps, taken in turn (0 = every map), so that with R robots each other map is asked every "
      "(R - 1) / other_maps_per_keyframe keyframes and the work per keyframe stays that of 1 + "
      "other_maps_per_keyframe queries however large the team. A revisit lasts many keyframes: it is still found, "
      "a few keyframes later. With two robots 1 asks every map. docs/multi_robot.md measures both.");
  }
  void validate() const { validateDeclared(*this); }
};

}  // namespace mild
