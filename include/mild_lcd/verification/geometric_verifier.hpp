#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/verification/candidate_verifier.hpp"
#include "mild_lcd/verification/sparse_matcher.hpp"

namespace mild {

struct VerificationParams {
  bool enabled = true;
  // How query and candidate are matched: sparse match with Lowe's ratio test at 0.8 (without it,
  // hundreds of raw nearest neighbours let wrong pairs collect tens of chance inliers).
  SparseMatchParams matching = withRatio(0.8);
  // Two-view model fitted with MAGSAC (OpenCV USAC): the fundamental matrix, or the essential
  // matrix when intrinsics fx, fy, cx, cy are given (fx > 0).
  double ransac_threshold = 1.0;  // pixels
  double confidence = 0.999;
  int max_iterations = 1000;
  // The camera's intrinsics when keyframes do not bring their own (Features::camera, e.g. from a
  // sensor_msgs/CameraInfo); a keyframe's own take precedence.
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;
  // Metric pose of a verified loop when the query's keypoints carry depth: PnP inlier threshold
  // (pixels in the candidate's image; looser than the two-view fit's, for the depth's own noise).
  double pnp_threshold = 3.0;
  // A candidate is verified when at least min_inliers matches agree with the model. On the bench,
  // 12..20 give the same recall@100%P; 15 sits in the middle.
  int min_inliers = 15;

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
  GeometricCheck check(const Features& query, const Features& candidate) const;

  // The model fit alone, on given matches (keypoints index the matches' query/train fields). The
  // features' descriptors are not used; their cameras and the query's depths are.
  GeometricCheck fit(const Features& query, const Features& train, std::vector<FeatureMatch> matches) const;
  GeometricCheck fit(const std::vector<cv::KeyPoint>& query, const std::vector<cv::KeyPoint>& train,
                     std::vector<FeatureMatch> matches) const;

 private:
  GeometricCheck fitViews(const std::vector<cv::KeyPoint>& query, const std::vector<cv::KeyPoint>& train,
                          const CameraIntrinsics& query_camera, const CameraIntrinsics& train_camera,
                          const std::vector<float>& query_depths, std::vector<FeatureMatch> matches) const;

  VerificationParams params_;
  mutable SparseMatcher matcher_;  // reusable buffers; the verifier is not thread-safe
};

}  // namespace mild
