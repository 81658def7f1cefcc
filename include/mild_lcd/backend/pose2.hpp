#pragma once

// A pose on the ground plane (x, y in metres, yaw in radians about z up) and the few SE(2)
// operations the example back-end needs. Header-only, no dependency.

#include <cmath>

namespace mild::backend {

constexpr double kPi = 3.14159265358979323846;

inline double wrapAngle(double a) { return std::atan2(std::sin(a), std::cos(a)); }

struct Pose2 {
  double x = 0.0, y = 0.0, yaw = 0.0;
};

// a * b: b expressed in a's frame, moved into a's parent frame.
inline Pose2 compose(const Pose2& a, const Pose2& b) {
  const double c = std::cos(a.yaw), s = std::sin(a.yaw);
  return {a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y, wrapAngle(a.yaw + b.yaw)};
}

inline Pose2 inverse(const Pose2& a) {
  const double c = std::cos(a.yaw), s = std::sin(a.yaw);
  return {-c * a.x - s * a.y, s * a.x - c * a.y, wrapAngle(-a.yaw)};
}

// b in a's frame: inverse(a) * b.
inline Pose2 between(const Pose2& a, const Pose2& b) { return compose(inverse(a), b); }

}  // namespace mild::backend
