#include "mild_lcd/verification/relative_pose.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>

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
