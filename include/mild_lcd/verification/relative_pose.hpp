#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace mild {

// Where the candidate's camera is, seen from the query's camera, as a pose-graph back-end needs it
// for a loop edge. Frames: OpenCV's camera axes (x right, y down, z forward; REP 103's optical
// frame). rotation maps directions in the candidate camera's frame into the query camera's, and
// translation is the candidate camera's centre in the query camera's frame, a unit vector: two views
// fix the direction of the baseline but not its length. `inliers` are the matches in front of both
// cameras (cheirality) under this pose.
struct RelativePose {
  bool valid = false;
  cv::Matx33d rotation = cv::Matx33d::eye();
  cv::Vec3d translation{0.0, 0.0, 0.0};
  int inliers = 0;
};

// Decomposes the essential matrix E of query -> candidate points (x_c^T E x_q = 0, as
// cv::findEssentialMat(query, candidate) returns it) and keeps the one of its four poses that puts
// the most points in front of both cameras. Invalid when fewer than min_inliers pass that test or
// the decomposition fails.
RelativePose relativePoseFromEssential(const cv::Mat& essential, const std::vector<cv::Point2f>& query_points,
                                       const std::vector<cv::Point2f>& candidate_points, const cv::Matx33d& camera,
                                       int min_inliers);

// Angle of the rotation a^T b, in degrees (0 when equal).
double rotationAngleDegrees(const cv::Matx33d& a, const cv::Matx33d& b);
// Angle between two directions, in degrees.
double directionAngleDegrees(const cv::Vec3d& a, const cv::Vec3d& b);

}  // namespace mild
