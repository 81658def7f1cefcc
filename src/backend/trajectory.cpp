#include "mild_lcd/backend/trajectory.hpp"

#include <cmath>
#include <random>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild::backend {

std::vector<Pose2> driftedOdometry(const std::vector<Pose2>& truth, const DriftModel& model) {
  std::vector<Pose2> out;
  if (truth.empty()) return out;
  std::mt19937_64 rng(model.seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  out.reserve(truth.size());
  out.push_back(truth.front());
  for (size_t i = 1; i < truth.size(); ++i) {
    const Pose2 step = between(truth[i - 1], truth[i]);
    const double d = std::hypot(step.x, step.y);
    Pose2 measured;
    measured.x = step.x * (1.0 + model.scale_error) + normal(rng) * model.translation_noise * d;
    measured.y = step.y * (1.0 + model.scale_error) + normal(rng) * model.translation_noise * d;
    measured.yaw = step.yaw + model.heading_bias * d + normal(rng) * model.heading_random_walk * std::sqrt(d);
    out.push_back(compose(out.back(), measured));
  }
  return out;
}

Pose2 alignTrajectory(const std::vector<Pose2>& estimate, const std::vector<Pose2>& truth) {
  if (estimate.size() != truth.size() || estimate.empty()) {
    throw InvalidInput("trajectory error: " + std::to_string(estimate.size()) + " estimated poses for " +
                       std::to_string(truth.size()) + " true ones");
  }
  const double n = static_cast<double>(estimate.size());
  double ex = 0, ey = 0, tx = 0, ty = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    ex += estimate[i].x / n;
    ey += estimate[i].y / n;
    tx += truth[i].x / n;
    ty += truth[i].y / n;
  }
  double dot = 0, cross = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    const double ax = estimate[i].x - ex, ay = estimate[i].y - ey, bx = truth[i].x - tx, by = truth[i].y - ty;
    dot += ax * bx + ay * by;
    cross += ax * by - ay * bx;
  }
  const double theta = std::atan2(cross, dot);
  const double c = std::cos(theta), s = std::sin(theta);
  return {tx - (c * ex - s * ey), ty - (s * ex + c * ey), theta};
}

double absoluteTrajectoryError(const std::vector<Pose2>& estimate, const std::vector<Pose2>& truth) {
  const Pose2 a = alignTrajectory(estimate, truth);
  double sum = 0.0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    const Pose2 p = compose(a, estimate[i]);
    sum += (p.x - truth[i].x) * (p.x - truth[i].x) + (p.y - truth[i].y) * (p.y - truth[i].y);
  }
  return std::sqrt(sum / static_cast<double>(estimate.size()));
}

double pathLength(const std::vector<Pose2>& trajectory) {
  double length = 0.0;
  for (size_t i = 1; i < trajectory.size(); ++i) {
    length += std::hypot(trajectory[i].x - trajectory[i - 1].x, trajectory[i].y - trajectory[i - 1].y);
  }
  return length;
}

}  // namespace mild::backend
