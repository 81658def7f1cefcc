#pragma once

// What measuring the example back-end takes: odometry with drift made from a ground-truth
// trajectory (a documented noise model and a seed), and the absolute trajectory error after
// alignment. ROS-free, no solver.

#include <cstdint>
#include <vector>

#include "mild_lcd/backend/pose2.hpp"

namespace mild::backend {

// Wheel-odometry-like drift, applied to each step between consecutive ground-truth poses (the
// step's translation d and yaw change in the earlier pose's frame):
//   translation' = translation x (1 + scale_error) + N(0, (translation_noise x |d|)^2) per component
//   yaw'         = yaw + heading_bias x |d| + N(0, heading_random_walk^2 x |d|)
// and integrated from the first ground-truth pose. scale_error is one constant of the run (a wrong
// wheel radius), heading_bias a constant turn per metre (a miscalibrated track width or gyro bias),
// heading_random_walk the heading's random walk in radians per square-root metre.
// The defaults: 1 % scale error, 1 % translation noise, 0.002 rad/m (0.11 degrees per metre: wheels
// whose radii differ by 0.1 % on a 0.5 m track) and 0.01 rad/sqrt(m) (0.57 degrees after 1 m, 5.7
// after 100 m). docs/pose_graph.md also measures a pure random walk of 0.02 rad/sqrt(m).
struct DriftModel {
  double scale_error = 0.01;
  double translation_noise = 0.01;
  double heading_bias = 0.002;
  double heading_random_walk = 0.01;
  uint64_t seed = 1;
};

std::vector<Pose2> driftedOdometry(const std::vector<Pose2>& truth, const DriftModel& model);

// Root mean square of the position errors after the rigid planar motion (rotation + translation,
// no scale) that best aligns `estimate` onto `truth` (least squares, closed form). Both the same
// length; throws InvalidInput otherwise or when empty.
double absoluteTrajectoryError(const std::vector<Pose2>& estimate, const std::vector<Pose2>& truth);

// The alignment itself: the pose A such that compose(A, estimate[i]) is closest to truth[i].
Pose2 alignTrajectory(const std::vector<Pose2>& estimate, const std::vector<Pose2>& truth);

// Distance travelled along a trajectory, metres.
double pathLength(const std::vector<Pose2>& trajectory);

}  // namespace mild::backend
