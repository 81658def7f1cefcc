#include "mild_lcd/verification/geometric_verifier.hpp"

#include <cmath>
#include <string>

#include <opencv2/calib3d.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/verification/inlier_layout.hpp"

namespace mild {
namespace {

// Fewest correspondences a fundamental (7/8-point) or essential (5-point) solver needs, with margin.
constexpr int kMinimalMatches = 8;

}  // namespace

void VerificationParams::validate() const {
  matching.validate();
  if (!(ransac_threshold > 0.0) || !std::isfinite(ransac_threshold)) {
    throw InvalidInput("verification/ransac_threshold must be a positive number of pixels");
  }
  if (!(confidence > 0.0 && confidence < 1.0)) throw InvalidInput("verification/confidence must be in (0, 1)");
  if (max_iterations < 1) throw InvalidInput("verification/max_iterations must be >= 1");
  if (min_inliers < kMinimalMatches) {
    throw InvalidInput("verification/min_inliers must be >= " + std::to_string(kMinimalMatches));
  }
  if (usesIntrinsics() &&
      !(fy > 0.0 && std::isfinite(fx) && std::isfinite(fy) && std::isfinite(cx) && std::isfinite(cy))) {
    throw InvalidInput("verification/fx, fy must both be positive (and cx, cy finite) to use the essential matrix");
  }
}

GeometricVerifier::GeometricVerifier(const VerificationParams& params)
    : params_((params.validate(), params)), matcher_(params.matching) {}

Verification GeometricVerifier::verify(const Features& query, const Features& candidate) const {
  return check(query, candidate).verification;
}

GeometricCheck GeometricVerifier::check(const Features& query, const Features& candidate) const {
  if (query.keypoints.size() != query.descriptors.size() ||
      candidate.keypoints.size() != candidate.descriptors.size()) {
    throw InvalidInput("geometric verification needs one keypoint per descriptor");
  }
  return fit(query.keypoints, candidate.keypoints, matcher_.match(query.descriptors, candidate.descriptors));
}

GeometricCheck GeometricVerifier::fit(const std::vector<cv::KeyPoint>& query, const std::vector<cv::KeyPoint>& train,
                                      std::vector<FeatureMatch> matches) const {
  GeometricCheck out;
  out.verification.attempted = true;
  out.verification.matches = static_cast<int>(matches.size());
  out.matches = std::move(matches);
  if (out.matches.size() < static_cast<size_t>(kMinimalMatches)) return out;

  std::vector<cv::Point2f> p1, p2;
  p1.reserve(out.matches.size());
  p2.reserve(out.matches.size());
  for (const FeatureMatch& m : out.matches) {
    if (m.query < 0 || m.train < 0 || static_cast<size_t>(m.query) >= query.size() ||
        static_cast<size_t>(m.train) >= train.size()) {
      throw InvalidInput("match refers to keypoint " + std::to_string(m.query) + "/" + std::to_string(m.train) +
                         " outside the " + std::to_string(query.size()) + "/" + std::to_string(train.size()) +
                         " given");
    }
    p1.push_back(query[m.query].pt);
    p2.push_back(train[m.train].pt);
  }
  cv::Mat mask;
  try {
    if (params_.usesIntrinsics()) {
      const cv::Matx33d k(params_.fx, 0, params_.cx, 0, params_.fy, params_.cy, 0, 0, 1);
      out.model = cv::findEssentialMat(p1, p2, k, cv::USAC_MAGSAC, params_.confidence, params_.ransac_threshold, mask);
    } else {
      out.model = cv::findFundamentalMat(p1, p2, cv::USAC_MAGSAC, params_.ransac_threshold, params_.confidence,
                                         params_.max_iterations, mask);
    }
  } catch (const cv::Exception&) {
    out.model.release();  // degenerate input (e.g. all points identical): no model, not verified
  }
  if (out.model.empty() || out.model.rows != 3 || mask.empty()) {
    out.model.release();
    return out;
  }
  out.inlier_mask.assign(mask.begin<uint8_t>(), mask.end<uint8_t>());
  int inliers = 0;
  std::vector<cv::Point2f> q_in, t_in;
  for (size_t i = 0; i < out.inlier_mask.size(); ++i) {
    if (!out.inlier_mask[i]) continue;
    ++inliers;
    out.verification.inlier_matches.push_back(out.matches[i]);
    q_in.push_back(p1[i]);
    t_in.push_back(p2[i]);
  }
  out.verification.coverage = std::min(inlierCoverage(query, q_in), inlierCoverage(train, t_in));
  out.verification.homography_share = homographyShare(q_in, t_in);
  out.verification.inliers = inliers;
  out.verification.inlier_ratio = static_cast<double>(inliers) / static_cast<double>(out.matches.size());
  out.verification.verified = inliers >= params_.min_inliers;
  if (out.verification.verified && params_.usesIntrinsics()) {
    const cv::Matx33d k(params_.fx, 0, params_.cx, 0, params_.fy, params_.cy, 0, 0, 1);
    out.verification.pose = relativePoseFromEssential(out.model, q_in, t_in, k, params_.min_inliers);
  }
  return out;
}

}  // namespace mild
