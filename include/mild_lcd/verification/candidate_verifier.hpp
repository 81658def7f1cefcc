#pragma once

#include <vector>

#include "mild_lcd/features/feature_match.hpp"
#include "mild_lcd/features/features.hpp"
#include "mild_lcd/verification/relative_pose.hpp"

namespace mild {

// Outcome of checking one loop candidate geometrically.
struct Verification {
  bool attempted = false;
  bool verified = false;
  int matches = 0;  // descriptor matches fed to the geometric model
  int inliers = 0;  // matches consistent with it
  double inlier_ratio = 0.0;
  double coverage = 0.0;                     // inlierCoverage, the smaller of the two images' (inlier_layout.hpp)
  double homography_share = 0.0;             // homographyShare of the inliers
  std::vector<FeatureMatch> inlier_matches;  // the matches consistent with the model
  std::vector<cv::Point2f> inlier_query_points, inlier_candidate_points;  // their pixels, in the same order
  RelativePose pose;  // of a verified candidate, when intrinsics are known
};

// The seam between loop detection and geometry: given the query's and a candidate's features,
// decide whether they see the same place.
class CandidateVerifier {
 public:
  virtual ~CandidateVerifier() = default;
  virtual Verification verify(const Features& query, const Features& candidate) const = 0;
  // Every candidate of one query, results in their order. One after another unless a verifier can
  // do better (GeometricVerifier: concurrently).
  virtual std::vector<Verification> verifyAll(const Features& query, const std::vector<Features>& candidates) const {
    std::vector<Verification> out;
    out.reserve(candidates.size());
    for (const Features& candidate : candidates) out.push_back(verify(query, candidate));
    return out;
  }
};

}  // namespace mild
