#include "mild_lcd/verification/relative_pose.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>

#include "mild_lcd/features/features.hpp"

namespace mild {

RelativePose relativePoseFromEssential(const cv::Mat& essential, const std::vector<cv::Point2f>& query_points,
                                       const std::vector<cv::Point2f>& candidate_points, const cv::Matx33d& camera,
                                       int min_inliers) {
  RelativePose pose;
  if (essential.empty() || essential.rows != 3 || essential.cols != 3 || query_points.size() < 5 ||
      query_points.size() != candidate_points.size()) {
    return pose;
  }
  cv::Mat r, t;
  int in_front = 0;
  try {
    // recoverPose gives the motion of points from the query's camera frame into the candidate's:
    // X_c = R X_q + t.
    in_front = cv::recoverPose(essential, query_points, candidate_points, cv::Mat(camera), r, t);
  } catch (const cv::Exception&) {
    return pose;
  }
  if (in_front < min_inliers || r.empty() || t.empty()) return pose;
  const cv::Matx33d r_cq(r);
  const cv::Vec3d t_cq(t);
  // The candidate camera in the query's frame: orientation R^T, centre -R^T t.
  pose.rotation = r_cq.t();
  cv::Vec3d centre = -(r_cq.t() * t_cq);
  const double norm = cv::norm(centre);
  if (!(norm > 0.0) || !std::isfinite(norm)) return pose;
  pose.translation = centre / norm;
  pose.inliers = in_front;
  pose.valid = true;
  return pose;
}

RelativePose relativePoseFromDepth(const std::vector<cv::Point2f>& query_points, const std::vector<float>& depths,
                                   const std::vector<cv::Point2f>& candidate_points, const cv::Matx33d& query_camera,
                                   const cv::Matx33d& candidate_camera, double threshold_px, int min_inliers) {
  RelativePose pose;
  if (query_points.size() != depths.size() || query_points.size() != candidate_points.size()) return pose;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  const cv::Matx33d back_project = query_camera.inv();
  for (size_t i = 0; i < depths.size(); ++i) {
    if (!depthKnown(depths[i])) continue;  // unknown, or outside the plausible range
    const double z = depths[i];
    const cv::Vec3d ray = back_project * cv::Vec3d(query_points[i].x, query_points[i].y, 1.0);
    object.emplace_back(ray[0] * z / ray[2], ray[1] * z / ray[2], z);
    image.emplace_back(candidate_points[i].x, candidate_points[i].y);
  }
  // EPnP needs 4 points and RANSAC some to spare; a loop edge worth weighting needs min_inliers.
  if (object.size() < static_cast<size_t>(std::max(min_inliers, 6))) return pose;
  cv::Mat rvec, tvec;
  std::vector<int> inliers;
  try {
    // X_c = R X_q + t: the query's points in the candidate camera's frame.
    const bool found = cv::solvePnPRansac(object, image, cv::Mat(candidate_camera), cv::noArray(), rvec, tvec, false,
                                          200, static_cast<float>(threshold_px), 0.999, inliers, cv::SOLVEPNP_EPNP);
    if (!found || inliers.size() < static_cast<size_t>(min_inliers)) return pose;
    std::vector<cv::Point3d> in_object;
    std::vector<cv::Point2d> in_image;
    for (int i : inliers) {
      in_object.push_back(object[i]);
      in_image.push_back(image[i]);
    }
    cv::solvePnPRefineLM(in_object, in_image, cv::Mat(candidate_camera), cv::noArray(), rvec, tvec);
    std::vector<cv::Point2d> projected;
    cv::projectPoints(in_object, rvec, tvec, cv::Mat(candidate_camera), cv::noArray(), projected);
    double sum = 0.0;
    for (size_t i = 0; i < projected.size(); ++i) {
      const cv::Point2d e = projected[i] - in_image[i];
      sum += e.dot(e);
    }
    pose.reprojection_error = std::sqrt(sum / static_cast<double>(projected.size()));
  } catch (const cv::Exception&) {
    return pose;
  }
  cv::Mat r;
  cv::Rodrigues(rvec, r);
  const cv::Matx33d r_cq(r);
  const cv::Vec3d t_cq(tvec);
  if (!std::isfinite(t_cq[0]) || !std::isfinite(t_cq[1]) || !std::isfinite(t_cq[2])) return pose;
  const cv::Vec3d centre = -(r_cq.t() * t_cq);
  // Two cameras that see the same points this far apart are a scale error, not a loop: no metric
  // pose (the essential matrix's direction is used instead).
  if (!(cv::norm(centre) <= kMaxMetricTranslationMetres)) return pose;
  pose.rotation = r_cq.t();
  pose.translation = centre;
  pose.inliers = static_cast<int>(inliers.size());
  pose.metric = true;
  pose.valid = true;
  return pose;
}

double rotationAngleDegrees(const cv::Matx33d& a, const cv::Matx33d& b) {
  const cv::Matx33d d = a.t() * b;
  const double c = std::clamp((cv::trace(d) - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c) * 180.0 / M_PI;
}

double directionAngleDegrees(const cv::Vec3d& a, const cv::Vec3d& b) {
  const double na = cv::norm(a), nb = cv::norm(b);
  if (!(na > 0.0) || !(nb > 0.0)) return 180.0;
  const double c = std::clamp(a.dot(b) / (na * nb), -1.0, 1.0);
  return std::acos(c) * 180.0 / M_PI;
}

}  // namespace mild
