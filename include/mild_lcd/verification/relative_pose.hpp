#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace mild {

// Where the candidate's camera is, seen from the query's camera, as a pose-graph back-end needs it
// for a loop edge. Frames: OpenCV's camera axes (x right, y down, z forward; REP 103's optical
// frame). rotation maps directions in the candidate camera's frame into the query camera's, and
// translation is the candidate camera's centre in the query camera's frame, a unit vector: two views
// fix the direction of the baseline but not its length, unless `metric`: then it is in metres,
// from PnP on the query's keypoints with known depth. `inliers` are the matches that support it (in
// front of both cameras for the essential matrix; within the reprojection threshold for PnP), and
// `reprojection_error` their RMS reprojection error in the candidate's image (pixels; PnP only).
struct RelativePose {
  bool valid = false;
  bool metric = false;
  cv::Matx33d rotation = cv::Matx33d::eye();
  cv::Vec3d translation{0.0, 0.0, 0.0};
  int inliers = 0;
  double reprojection_error = 0.0;
};

// Decomposes the essential matrix E of query -> candidate points (x_c^T E x_q = 0, as
// cv::findEssentialMat(query, candidate) returns it) and keeps the one of its four poses that puts
// the most points in front of both cameras. Invalid when fewer than min_inliers pass that test or
// the decomposition fails.
RelativePose relativePoseFromEssential(const cv::Mat& essential, const std::vector<cv::Point2f>& query_points,
                                       const std::vector<cv::Point2f>& candidate_points, const cv::Matx33d& camera,
                                       int min_inliers);

// The longest metric translation published: the farthest depth a keypoint may have
// (features/features.hpp).
constexpr double kMaxMetricTranslationMetres = 1e4;

// Metric pose from the query's keypoints with depth (back-projected with query_camera into the
// query's frame) and their matches in the candidate's image: PnP in a RANSAC loop (reprojection
// threshold in pixels), refined on its inliers. depths[i] belongs to query_points[i]; points whose
// depth is unknown (depthKnown false: 0, not finite, outside [kMinDepthMetres, kMaxDepthMetres])
// are left out. Invalid when fewer than min_inliers remain, or when the translation is not finite
// or longer than kMaxMetricTranslationMetres.
RelativePose relativePoseFromDepth(const std::vector<cv::Point2f>& query_points, const std::vector<float>& depths,
                                   const std::vector<cv::Point2f>& candidate_points, const cv::Matx33d& query_camera,
                                   const cv::Matx33d& candidate_camera, double threshold_px, int min_inliers);

// Angle of the rotation a^T b, in degrees (0 when equal).
double rotationAngleDegrees(const cv::Matx33d& a, const cv::Matx33d& b);
// Angle between two directions, in degrees.
double directionAngleDegrees(const cv::Vec3d& a, const cv::Vec3d& b);

}  // namespace mild
