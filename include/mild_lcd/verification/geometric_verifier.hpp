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
      "Geometric verification of every reported candidate: sparse match (MIH, seed paper IV.B) of query and "
      "candidate, then a two-view model fitted robustly (verification/method). Candidates that fail it are still "
      "reported (verified "
      "= false), with the low probability their few inliers give (scoring/); only verified ones are accepted. "
      "Its inlier count is the published probability's evidence that means the same on real frames as on "
      "renders (docs/accuracy.md).");
    SparseMatchParams::declare(p.matching, v);
    v("method", p.method, Bounds::oneOf(robustMethods()),
      "Model fit: OpenCV's robust estimator. usac_fast (USAC_FAST: RANSAC with few local-optimisation steps), "
      "magsac (USAC_MAGSAC, the default before 2026-12), usac (USAC_DEFAULT), usac_prosac (USAC_PROSAC, "
      "matches ordered by descriptor distance), ransac (classic RANSAC). On the bench's real and public "
      "sequences usac_fast took 0.79 of magsac's CPU per keyframe with recall@100%P and AP within 0.01 on every "
      "sequence (docs/speed.md, \"What each stage costs\").");
    v("ransac_threshold", p.ransac_threshold, Bounds::above(0).runtime(), "Model fit: inlier threshold in pixels.");
    v("confidence", p.confidence, Bounds::between(0, 1), "Model fit: RANSAC confidence.");
    v("max_iterations", p.max_iterations, Bounds::atLeast(1), "Model fit: iteration cap.");
    v("min_inliers", p.min_inliers, Bounds::atLeast(kMinimalMatches).runtime(),
      "Verified when at least this many matches agree with the model. On the bench 12..20 give the same "
      "recall@100%P; 15 sits in the middle.");
    v("fx", p.fx, Bounds::any(),
      "Camera intrinsics in pixels, for keyframes that bring none (a CameraInfo beside the image, "
      "Keyframe.camera_info take precedence). With fx > 0 the essential matrix is fitted instead of the "
      "fundamental matrix, and verified loops carry a relative pose.");
    v("fy", p.fy, Bounds::any(), "Focal length in y, in pixels (with fx).");
    v("cx", p.cx, Bounds::any(), "Principal point x, in pixels (with fx).");
    v("cy", p.cy, Bounds::any(), "Principal point y, in pixels (with fx).");
    v("pnp_threshold", p.pnp_threshold, Bounds::above(0).runtime(),
      "When the query's keypoints have depth (Keyframe.depths), the relative pose of a verified loop is metric, "
      "from PnP with this inlier threshold in pixels.");
    v("parallel_candidates", p.parallel_candidates, Bounds::any(),
      "Verify one keyframe's candidates concurrently, on OpenCV's worker threads (cv::getNumThreads(): the cores, "
      "unless the process set fewer). The same results either way; on two cores three candidates take about 0.7 "
      "of the time, but in the soak at 30 Hz on two cores the node dropped keyframes with it and none without it, "
      "so it is off by default (docs/speed.md, \"Verification on two cores\").");
    v("early_stop", p.early_stop, Bounds::any(),
      "Fit a candidate's model only when it could matter: after its descriptor matches, a candidate whose "
      "published probability stays below scoring/decision_probability even if every match were an inlier, and "
      "below a candidate of the same keyframe already verified, is reported unfitted "
      "(fit_skipped in mild_offline --details). What is accepted, and each keyframe's best candidate, are the same "
      "either way; "
      "the rest of the candidates' probabilities may be lower. Off (false) when fitting the scorer: its "
      "training data need every candidate's inliers.");
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
