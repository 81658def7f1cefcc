#pragma once

// Trajectories with known truth for the example back-end's tests: three laps of a rectangle, the
// loop measurement the detector would publish between two of its poses, a loop's candidate.

#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "mild_lcd/backend/pose_graph.hpp"

namespace mild::backend {

// Three laps around a 12 x 8 m rectangle, each lap 0.6 m further out, 0.4 m steps, the heading
// along the edge.
inline std::vector<Pose2> threeLaps() {
  std::vector<Pose2> poses;
  for (int lap = 0; lap < 3; ++lap) {
    const double grow = 0.6 * lap, w = 12.0 + 2 * grow, h = 8.0 + 2 * grow;
    const double x0 = -grow, y0 = -grow;
    const double corners[4][2] = {{x0, y0}, {x0 + w, y0}, {x0 + w, y0 + h}, {x0, y0 + h}};
    for (int side = 0; side < 4; ++side) {
      const double* a = corners[side];
      const double* b = corners[(side + 1) % 4];
      const double length = std::hypot(b[0] - a[0], b[1] - a[1]);
      const double yaw = std::atan2(b[1] - a[1], b[0] - a[0]);
      const int steps = static_cast<int>(std::round(length / 0.4));
      for (int k = 0; k < steps; ++k) {
        const double f = static_cast<double>(k) / steps;
        poses.push_back({a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), yaw});
      }
    }
  }
  return poses;
}

// What the detector would publish for two keyframes whose bases are at query and candidate: the
// candidate camera's pose in the query camera's optical frame; a unit translation unless metric.
inline LoopMeasurement measure(const Pose2& query, const Pose2& candidate, uint64_t qi, uint64_t ci, bool metric,
                               const Extrinsics& e = Extrinsics::forwardLooking()) {
  const Pose2 rel = between(query, candidate);
  const Eigen::Matrix3d rz = Eigen::AngleAxisd(rel.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d t(rel.x, rel.y, 0.0);
  LoopMeasurement m;
  m.query = qi;
  m.candidate = ci;
  m.rotation = Eigen::Quaterniond(e.rotation.transpose() * rz * e.rotation);
  Eigen::Vector3d centre = e.rotation.transpose() * (rz * e.translation + t - e.translation);
  if (!metric) centre.normalize();
  m.translation = centre;
  m.metric = metric;
  return m;
}

// The pose of lap 0 nearest to pose i (a loop's candidate).
inline size_t nearestInFirstLap(const std::vector<Pose2>& poses, size_t i, size_t lap_length) {
  size_t best = 0;
  double best_d = 1e9;
  for (size_t j = 0; j < lap_length; ++j) {
    const double d = std::hypot(poses[j].x - poses[i].x, poses[j].y - poses[i].y);
    if (d < best_d) best_d = d, best = j;
  }
  return best;
}

}  // namespace mild::backend
