#include "mild_lcd/verification/geometric_verifier.hpp"

#include <algorithm>
#include <cmath>
#include <exception>
#include <string>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/verification/chance_agreement.hpp"
#include "mild_lcd/verification/inlier_layout.hpp"

namespace mild {
namespace {

// Fewest correspondences a fundamental (7/8-point) or essential (5-point) solver needs, with margin.
constexpr int kMinimalMatches = VerificationParams::kMinimalMatches;

struct RobustMethod {
  const char* name;
  int flag;  // cv::USAC_* or cv::RANSAC
};
// One row per estimator verification/method accepts.
constexpr RobustMethod kRobustMethods[] = {
    {"magsac", cv::USAC_MAGSAC},      {"usac", cv::USAC_DEFAULT}, {"usac_fast", cv::USAC_FAST},
    {"usac_prosac", cv::USAC_PROSAC}, {"ransac", cv::RANSAC},
};

int robustMethodFlag(const std::string& name) {
  for (const RobustMethod& m : kRobustMethods) {
    if (name == m.name) return m.flag;
  }
  throw InvalidInput("verification/method " + name + " is not one of the robust estimators");
}

}  // namespace

const std::vector<std::string>& robustMethods() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> out;
    for (const RobustMethod& m : kRobustMethods) out.emplace_back(m.name);
    return out;
  }();
  return names;
}

void VerificationParams::validate() const {
  validateDeclared(*this);
  matching.validate();
  if (usesIntrinsics() &&
      !(fy > 0.0 && std::isfinite(fx) && std::isfinite(fy) && std::isfinite(cx) && std::isfinite(cy))) {
    throw InvalidInput("verification/fx, fy must both be positive (and cx, cy finite) to use the essential matrix");
  }
}

GeometricVerifier::GeometricVerifier(const VerificationParams& params)
    : params_((params.validate(), params)), matchers_(1, SparseMatcher(params.matching)) {}

Verification GeometricVerifier::verify(const Features& query, const Features& candidate) const {
  return check(query, candidate).verification;
}

std::vector<Verification> GeometricVerifier::verifyAll(const Features& query, const std::vector<Features>& candidates,
                                                       const NeedsFit& needs_fit) const {
  const int n = static_cast<int>(candidates.size());
  if (!params_.parallel_candidates || n < 2 || cv::getNumThreads() < 2) {
    std::vector<Verification> out;
    out.reserve(candidates.size());
    for (size_t i = 0; i < candidates.size(); ++i) {
      const Features& candidate = candidates[i];
      std::vector<FeatureMatch> matches = matchWith(matchers_.front(), query, candidate);
      if (needs_fit && !needs_fit(i, static_cast<int>(matches.size()), out)) {
        Verification skipped;
        skipped.attempted = true;
        skipped.fit_skipped = true;
        skipped.matches = static_cast<int>(matches.size());
        out.push_back(std::move(skipped));
        continue;
      }
      out.push_back(fit(query, candidate, std::move(matches)).verification);
    }
    return out;
  }
  std::vector<Verification> out(candidates.size());
  while (matchers_.size() < candidates.size()) matchers_.emplace_back(params_.matching);
  std::vector<std::exception_ptr> failures(candidates.size());
  // One stripe per candidate: each runs on one thread with a matcher of its own.
  cv::parallel_for_(
      cv::Range(0, n),
      [&](const cv::Range& range) {
        for (int i = range.start; i < range.end; ++i) {
          try {
            out[i] = checkWith(matchers_[i], query, candidates[i]).verification;
          } catch (...) {
            failures[i] = std::current_exception();
          }
        }
      },
      n);
  for (const std::exception_ptr& failure : failures) {
    if (failure) std::rethrow_exception(failure);
  }
  return out;
}

GeometricCheck GeometricVerifier::check(const Features& query, const Features& candidate) const {
  return checkWith(matchers_.front(), query, candidate);
}

std::vector<FeatureMatch> GeometricVerifier::matchWith(SparseMatcher& matcher, const Features& query,
                                                       const Features& candidate) {
  if (query.keypoints.size() != query.descriptors.size() ||
      candidate.keypoints.size() != candidate.descriptors.size()) {
    throw InvalidInput("geometric verification needs one keypoint per descriptor");
  }
  return matcher.match(query.descriptors, candidate.descriptors);
}

GeometricCheck GeometricVerifier::checkWith(SparseMatcher& matcher, const Features& query,
                                            const Features& candidate) const {
  return fit(query, candidate, matchWith(matcher, query, candidate));
}

GeometricCheck GeometricVerifier::fit(const Features& query, const Features& train,
                                      std::vector<FeatureMatch> matches) const {
  checkCameraAndDepths(query);
  checkCameraAndDepths(train);
  // A keyframe's own intrinsics first; then the configured ones; then the other view's (one camera).
  const CameraIntrinsics configured = params_.intrinsics();
  const auto resolve = [&](const CameraIntrinsics& own, const CameraIntrinsics& other) {
    return own.known() ? own : configured.known() ? configured : other;
  };
  return fitViews(query.keypoints, train.keypoints, detectionScale(query, train), resolve(query.camera, train.camera),
                  resolve(train.camera, query.camera), query.depths, std::move(matches));
}

double GeometricVerifier::detectionScale(const Features& query, const Features& train) {
  return std::max(boundedDetectionScale(query.detection_scale), boundedDetectionScale(train.detection_scale));
}

GeometricCheck GeometricVerifier::fit(const std::vector<cv::KeyPoint>& query, const std::vector<cv::KeyPoint>& train,
                                      std::vector<FeatureMatch> matches) const {
  const CameraIntrinsics configured = params_.intrinsics();
  return fitViews(query, train, 1.0, configured, configured, {}, std::move(matches));
}

namespace {

std::vector<cv::Point2f> normalised(const std::vector<cv::Point2f>& points, const CameraIntrinsics& camera) {
  std::vector<cv::Point2f> out;
  out.reserve(points.size());
  for (const cv::Point2f& p : points) {
    out.emplace_back(static_cast<float>((p.x - camera.cx) / camera.fx),
                     static_cast<float>((p.y - camera.cy) / camera.fy));
  }
  return out;
}

// The matched keypoints' image positions, query side and train side, in match order.
void matchedPoints(const std::vector<cv::KeyPoint>& query, const std::vector<cv::KeyPoint>& train,
                   const std::vector<FeatureMatch>& matches, std::vector<cv::Point2f>& p1,
                   std::vector<cv::Point2f>& p2) {
  p1.reserve(matches.size());
  p2.reserve(matches.size());
  for (const FeatureMatch& m : matches) {
    if (m.query < 0 || m.train < 0 || static_cast<size_t>(m.query) >= query.size() ||
        static_cast<size_t>(m.train) >= train.size()) {
      throw InvalidInput("match refers to keypoint " + std::to_string(m.query) + "/" + std::to_string(m.train) +
                         " outside the " + std::to_string(query.size()) + "/" + std::to_string(train.size()) +
                         " given");
    }
    p1.push_back(query[m.query].pt);
    p2.push_back(train[m.train].pt);
  }
}

// PROSAC samples the best-ranked matches first: nearest descriptors first.
void orderByDistance(std::vector<FeatureMatch>& matches, std::vector<cv::Point2f>& p1, std::vector<cv::Point2f>& p2) {
  std::vector<size_t> order(matches.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return matches[a].distance < matches[b].distance; });
  std::vector<FeatureMatch> sorted;
  std::vector<cv::Point2f> s1, s2;
  for (size_t i : order) {
    sorted.push_back(matches[i]);
    s1.push_back(p1[i]);
    s2.push_back(p2[i]);
  }
  matches = std::move(sorted);
  p1 = std::move(s1);
  p2 = std::move(s2);
}

// The two-view model (E with both cameras known, else F) and its inlier mask; an empty model for
// degenerate input (e.g. all points identical).
cv::Mat fitTwoViewModel(const std::vector<cv::Point2f>& p1, const std::vector<cv::Point2f>& p2,
                        const CameraIntrinsics& query_camera, const CameraIntrinsics& train_camera,
                        const VerificationParams& params, double tolerance_px, cv::Mat& mask) {
  const bool essential = query_camera.known() && train_camera.known();
  // Two different cameras (e.g. two robots): fit E to normalised image coordinates, with the
  // threshold scaled as OpenCV does for one camera (by the mean focal length).
  const bool two_cameras = essential && query_camera != train_camera;
  const double mean_focal = (query_camera.fx + query_camera.fy + train_camera.fx + train_camera.fy) / 4.0;
  const int method = robustMethodFlag(params.method);
  cv::Mat model;
  try {
    if (two_cameras) {
      model = cv::findEssentialMat(normalised(p1, query_camera), normalised(p2, train_camera), cv::Matx33d::eye(),
                                   method, params.confidence, tolerance_px / mean_focal, mask);
    } else if (essential) {
      model = cv::findEssentialMat(p1, p2, query_camera.matrix(), method, params.confidence, tolerance_px, mask);
    } else {
      model = cv::findFundamentalMat(p1, p2, method, tolerance_px, params.confidence, params.max_iterations, mask);
    }
  } catch (const cv::Exception&) {
    model.release();
  }
  return model;
}

}  // namespace

GeometricCheck GeometricVerifier::fitViews(const std::vector<cv::KeyPoint>& query,
                                           const std::vector<cv::KeyPoint>& train, double pixel_scale,
                                           const CameraIntrinsics& query_camera, const CameraIntrinsics& train_camera,
                                           const std::vector<float>& query_depths,
                                           std::vector<FeatureMatch> matches) const {
  GeometricCheck out;
  const double tolerance_px = params_.ransac_threshold * pixel_scale;
  out.verification.attempted = true;
  out.verification.matches = static_cast<int>(matches.size());
  out.matches = std::move(matches);
  if (out.matches.size() < static_cast<size_t>(kMinimalMatches)) return out;

  std::vector<cv::Point2f> p1, p2;
  matchedPoints(query, train, out.matches, p1, p2);
  if (robustMethodFlag(params_.method) == cv::USAC_PROSAC) orderByDistance(out.matches, p1, p2);
  cv::Mat mask;
  out.model = fitTwoViewModel(p1, p2, query_camera, train_camera, params_, tolerance_px, mask);
  if (out.model.empty() || out.model.rows != 3 || mask.empty()) {
    out.model.release();
    return out;
  }
  out.inlier_mask.assign(mask.begin<uint8_t>(), mask.end<uint8_t>());
  int inliers = 0;
  std::vector<cv::Point2f> q_in, t_in;
  std::vector<float> depth_in;
  for (size_t i = 0; i < out.inlier_mask.size(); ++i) {
    if (!out.inlier_mask[i]) continue;
    ++inliers;
    out.verification.inlier_matches.push_back(out.matches[i]);
    q_in.push_back(p1[i]);
    t_in.push_back(p2[i]);
    if (!query_depths.empty()) depth_in.push_back(query_depths[out.matches[i].query]);
  }
  out.verification.inlier_query_points = q_in;
  out.verification.inlier_candidate_points = t_in;
  out.verification.inliers = inliers;
  out.verification.inlier_ratio = static_cast<double>(inliers) / static_cast<double>(out.matches.size());
  const bool essential = query_camera.known() && train_camera.known();
  // The inliers against chance: the fit's tolerance in pixels over the area either image's keypoints
  // occupy, for the model's minimal sample.
  const double chance =
      (chanceInlierProbability(query, tolerance_px) + chanceInlierProbability(train, tolerance_px)) / 2.0;
  out.verification.log10_false_alarms =
      log10FalseAlarms(out.verification.matches, inliers, chance, essential ? kEssentialSample : kFundamentalSample);
  out.verification.verified = inliers >= params_.min_inliers;
  if (!out.verification.verified) return out;
  // The layout of the inliers describes a loop, not a rejection: a homography fit per rejected
  // candidate was a fifth of verification on real frames, for figures nothing reads.
  out.verification.coverage = std::min(inlierCoverage(query, q_in), inlierCoverage(train, t_in));
  out.verification.homography_share = homographyShare(q_in, t_in);
  if (!essential) return out;
  if (!depth_in.empty()) {
    out.verification.pose = relativePoseFromDepth(q_in, depth_in, t_in, query_camera.matrix(), train_camera.matrix(),
                                                  params_.pnp_threshold * pixel_scale, params_.min_inliers);
  }
  if (!out.verification.pose.valid) {  // no depth, or too little of it: the direction of the baseline
    const bool two_cameras = query_camera != train_camera;
    out.verification.pose =
        two_cameras ? relativePoseFromEssential(out.model, normalised(q_in, query_camera),
                                                normalised(t_in, train_camera), cv::Matx33d::eye(), params_.min_inliers)
                    : relativePoseFromEssential(out.model, q_in, t_in, query_camera.matrix(), params_.min_inliers);
  }
  return out;
}

}  // namespace mild
