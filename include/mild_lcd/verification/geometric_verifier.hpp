#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/verification/candidate_verifier.hpp"
#include "mild_lcd/verification/sparse_matcher.hpp"

namespace mild {

// The robust estimators verification/method may name, in OpenCV's terms (geometric_verifier.cpp).
const std::vector<std::string>& robustMethods();

struct VerificationParams {
  bool enabled = true;
  // How query and candidate are matched: sparse match with Lowe's ratio test at 0.8 (without it,
  // hundreds of raw nearest neighbours let wrong pairs collect tens of chance inliers).
  SparseMatchParams matching = withRatio(0.8);
  std::string method = "usac_fast";  // the robust estimator: robustMethods() (geometric_verifier.cpp)
  double ransac_threshold = 1.0;
  double confidence = 0.999;
  int max_iterations = 1000;
  int min_inliers = 15;
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
  double pnp_threshold = 3.0;
  bool parallel_candidates = false;
  bool early_stop = true;

  static constexpr int kMinimalMatches = 8;  // the eight-point minimum of a two-view model
  static constexpr const char* kSection = "verification";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("enabled", p.enabled, Bounds::any(),
      "Whether every reported candidate is verified (sparse match, then a robust two-view fit, "
      "verification/method), only verified candidates being accepted (true or false).");
    SparseMatchParams::declare(p.matching, v);
    v("method", p.method, Bounds::oneOf(robustMethods()),
      "Model fit: OpenCV's robust estimator, usac_fast (USAC_FAST), magsac (USAC_MAGSAC), usac (USAC_DEFAULT), "
      "usac_prosac (USAC_PROSAC) or ransac.");
    v("ransac_threshold", p.ransac_threshold, Bounds::above(0).runtime(), "Model fit: inlier threshold (pixels, > 0).");
    v("confidence", p.confidence, Bounds::between(0, 1),
      "Model fit: RANSAC confidence (probability, above 0 and below 1).");
    v("max_iterations", p.max_iterations, Bounds::atLeast(1), "Model fit: iteration cap (iterations, >= 1).");
    v("min_inliers", p.min_inliers, Bounds::atLeast(kMinimalMatches).runtime(),
      "A candidate is verified when at least this many matches agree with the model (matches, >= 8).");
    v("fx", p.fx, Bounds::any(),
      "Focal length in x for keyframes that bring no intrinsics, with which an essential matrix is fitted and "
      "verified loops carry a relative pose (pixels, 0 = none).");
    v("fy", p.fy, Bounds::any(), "Focal length in y, in pixels (with fx).");
    v("cx", p.cx, Bounds::any(), "Principal point x, in pixels (with fx).");
    v("cy", p.cy, Bounds::any(), "Principal point y, in pixels (with fx).");
    v("pnp_threshold", p.pnp_threshold, Bounds::above(0).runtime(),
      "Inlier threshold of the PnP fit that makes a verified loop's relative pose metric when the query's "
      "keypoints have depth (pixels, > 0).");
    v("parallel_candidates", p.parallel_candidates, Bounds::any(),
      "Whether one keyframe's candidates are verified concurrently on OpenCV's worker threads, with the same "
      "results (true or false).");
    v("early_stop", p.early_stop, Bounds::any(),
      "Whether the model fit is skipped for a candidate that could be neither accepted nor its keyframe's best "
      "even if every match were an inlier (true or false; false to fit the scorer).");
  }

  bool usesIntrinsics() const { return fx > 0.0; }
  CameraIntrinsics intrinsics() const { return {fx, fy, cx, cy}; }
  static SparseMatchParams withRatio(double ratio) {
    SparseMatchParams p;
    p.ratio = ratio;
    return p;
  }
  void validate() const;  // throws InvalidInput naming the first invalid field
};

// Everything the check found, for clients that want more than the verdict (the sparse-match
// service, the debug image).
struct GeometricCheck {
  Verification verification;
  std::vector<FeatureMatch> matches;
  std::vector<uint8_t> inlier_mask;  // one per match; empty when no model was fitted
  cv::Mat model;                     // 3x3 F or E (CV_64F), empty when none
};

// Sparse match of query against candidate, then a robust two-view model.
class GeometricVerifier : public CandidateVerifier {
 public:
  explicit GeometricVerifier(const VerificationParams& params);
  const VerificationParams& params() const { return params_; }

  Verification verify(const Features& query, const Features& candidate) const override;
  // With parallel_candidates, one matcher per candidate and the candidates spread over OpenCV's
  // threads (every one fitted); an exception from any of them is rethrown (the first by candidate
  // order). Otherwise one after another, each matched and then fitted unless `needs_fit` declines.
  std::vector<Verification> verifyAll(const Features& query, const std::vector<Features>& candidates,
                                      const NeedsFit& needs_fit = {}) const override;
  GeometricCheck check(const Features& query, const Features& candidate) const;

  // The model fit alone, on given matches (keypoints index the matches' query/train fields). The
  // features' descriptors are not used; their cameras and the query's depths are.
  GeometricCheck fit(const Features& query, const Features& train, std::vector<FeatureMatch> matches) const;
  GeometricCheck fit(const std::vector<cv::KeyPoint>& query, const std::vector<cv::KeyPoint>& train,
                     std::vector<FeatureMatch> matches) const;

 private:
  // pixel_scale widens the inlier tolerances (verification/ransac_threshold, pnp_threshold), which
  // are in the pixels keypoints were detected in: detectionScale.
  GeometricCheck fitViews(const std::vector<cv::KeyPoint>& query, const std::vector<cv::KeyPoint>& train,
                          double pixel_scale, const CameraIntrinsics& query_camera,
                          const CameraIntrinsics& train_camera, const std::vector<float>& query_depths,
                          std::vector<FeatureMatch> matches) const;
  // The sparse match alone, after checking that each side has one keypoint per descriptor.
  static std::vector<FeatureMatch> matchWith(SparseMatcher& matcher, const Features& query, const Features& candidate);
  GeometricCheck checkWith(SparseMatcher& matcher, const Features& query, const Features& candidate) const;
  // The coarser side's Features::detection_scale (boundedDetectionScale: 1 to 64): a keypoint found on an image shrunk
  // by s is placed 1/s less precisely in the frame, so the tolerances widen by 1/s.
  static double detectionScale(const Features& query, const Features& train);

  VerificationParams params_;
  // Reusable buffers, the first for check() and verify(), one per candidate in verifyAll(); the
  // verifier itself is not thread-safe.
  mutable std::vector<SparseMatcher> matchers_;
};

}  // namespace mild
