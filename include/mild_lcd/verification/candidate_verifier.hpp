#pragma once

#include <functional>
#include <vector>

#include "mild_lcd/features/feature_match.hpp"
#include "mild_lcd/features/features.hpp"
#include "mild_lcd/verification/relative_pose.hpp"

namespace mild {

// Outcome of checking one loop candidate geometrically.
struct Verification {
  bool attempted = false;
  bool verified = false;
  // No model was fitted: the descriptor matches alone showed that no fit could change the answer
  // (CandidateVerifier::NeedsFit). `matches` is set, `inliers` is 0.
  bool fit_skipped = false;
  int matches = 0;  // descriptor matches fed to the geometric model
  int inliers = 0;  // matches consistent with it
  double inlier_ratio = 0.0;
  // log10 of the model's number of false alarms given the matches, the tolerance and the image area
  // (chance_agreement.hpp): the inliers measured against chance, the same scale for every descriptor,
  // feature budget and resolution. 0 without a model or with no more inliers than its minimal sample.
  double log10_false_alarms = 0.0;
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
  // Asked before fitting candidate `index` with `matches` descriptor matches, given the
  // verifications of the candidates before it: false skips the fit (the caller knows that even
  // `matches` inliers could not make it count). Empty: every candidate is fitted.
  using NeedsFit = std::function<bool(size_t index, int matches, const std::vector<Verification>& earlier)>;

  virtual ~CandidateVerifier() = default;
  virtual Verification verify(const Features& query, const Features& candidate) const = 0;
  // Every candidate of one query, results in their order. One after another unless a verifier can
  // do better (GeometricVerifier: concurrently, or skipping the fits `needs_fit` declines).
  virtual std::vector<Verification> verifyAll(const Features& query, const std::vector<Features>& candidates,
                                              const NeedsFit& needs_fit = {}) const {
    (void)needs_fit;  // a verifier that cannot split matching from fitting fits every candidate
    std::vector<Verification> out;
    out.reserve(candidates.size());
    for (const Features& candidate : candidates) out.push_back(verify(query, candidate));
    return out;
  }
};

}  // namespace mild
