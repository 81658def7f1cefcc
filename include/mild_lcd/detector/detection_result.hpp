#pragma once

// What the detector answers for a keyframe: its candidates (each with its probability, verdict and
// verification), the step's statistics and the similarity.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "mild_lcd/common/types.hpp"
#include "mild_lcd/place/keyframe_database.hpp"
#include "mild_lcd/verification/candidate_verifier.hpp"

namespace mild {

struct LoopCandidate {
  uint64_t id = 0;          // the candidate keyframe's id
  uint32_t session = 0;     // and its session
  uint32_t robot = 0;       // and the robot whose map holds it (RobotTeam; 0 for a lone detector)
  KeyframeIndex index = 0;  // its position in the database
  double stamp = 0.0;
  double probability = 0.0;         // calibrated loop probability (CandidateScorer)
  double filter_probability = 0.0;  // the temporal filter's probability, one of its inputs
  double similarity = 0.0;          // Phi' of the query against this keyframe
  double saliency = 0.0;            // its robust z among the query's eligible keyframes (robustSaliency)
  size_t eligible_keyframes = 0;    // how many keyframes of its map were eligible (and compared)
  // The significance of the most significant other distinct place of its map verified on purpose
  // (CandidateScorer::Evidence::other_place_significance).
  double other_place_significance = 0.0;
  bool accepted = false;      // probability >= scoring/decision_probability (so verified, when verifying)
  Verification verification;  // geometric check (verified=false, inliers=0 when verification is off)
};

struct StepStats {
  double extract_ms = 0.0;
  double query_ms = 0.0;
  double filter_ms = 0.0;
  double verify_ms = 0.0;
  size_t features = 0;
  size_t eligible_keyframes = 0;
  size_t near_past_keyframes = 0;  // removed from the eligible ones by the near-past band
  // The keyframe's stamp was below the previous one's of the running session: its clock stepped
  // back, counted as no time passing (SessionClock).
  bool clock_stepped_back = false;
  // Its depths that were given but are not plausible (finite, not 0, outside [kMinDepthMetres,
  // kMaxDepthMetres]): taken as unknown (features/features.hpp).
  size_t depths_out_of_range = 0;
  QueryStats query;
};

struct DetectionResult {
  uint64_t query_id = 0;
  uint32_t query_session = 0;
  uint32_t query_robot = 0;  // RobotTeam: the robot that saw the query
  KeyframeIndex query_index = 0;
  std::vector<LoopCandidate> candidates;  // best first
  // The candidates that were verified and scored but fell beyond max_candidates, best first: not
  // reported, kept for evaluation (mild_offline --fit-every-candidate writes them as training data).
  std::vector<LoopCandidate> unreported;
  std::vector<double> similarity;  // Phi' against every eligible keyframe (by database index)
  StepStats stats;
};

}  // namespace mild
