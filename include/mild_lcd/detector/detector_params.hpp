#pragma once

// The detector's parameters, every section of them: the type alone. How they are declared, loaded,
// validated and printed is detector/detector_parameters.hpp, which includes this and nothing of the
// pipeline; the pipeline (detector/loop_detector.hpp) includes this too.

#include "mild_lcd/detector/candidate_params.hpp"
#include "mild_lcd/detector/candidate_scorer.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/filter/filters.hpp"
#include "mild_lcd/place/keyframe_database.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace mild {

struct DetectorParams {
  FeatureParams features;
  // database.descriptor_bytes is not read: the detector's database takes its width from `features`.
  DatabaseParams database;
  FilterParams filter;
  CandidateParams candidates;
  VerificationParams verification;
  ScoringParams scoring;
  SearchMode search = SearchMode::kIndex;

  // The database parameters the detector runs with: `database` at the features' width.
  DatabaseParams databaseParams() const;
  void validate() const;
};

}  // namespace mild
