#include "mild_lcd/offline/pose_evaluation.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

// Columns: the camera's x (right), y (down), z (forward) axes in world coordinates (z up).
cv::Matx33d cameraToWorld(const PlanarPose& p) {
  const double c = std::cos(p.yaw), s = std::sin(p.yaw);
  return cv::Matx33d(s, 0.0, c,   //
                     -c, 0.0, s,  //
                     0.0, -1.0, 0.0);
}

}  // namespace

std::vector<PlanarPose> loadPlanarPoses(const std::string& path, long expected_frames) {
  std::ifstream in(path);
  if (!in) throw InvalidInput(path + ": cannot read the poses file");
  std::vector<PlanarPose> poses;
  std::string line;
  size_t number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    PlanarPose p;
    if (!(fields >> p.x >> p.y >> p.yaw) || !std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.yaw)) {
      throw InvalidInput(path + ":" + std::to_string(number) + ": expected 'x y yaw' (three finite numbers)");
    }
    poses.push_back(p);
  }
  if (expected_frames >= 0 && poses.size() != static_cast<size_t>(expected_frames)) {
    throw InvalidInput(path + ": " + std::to_string(poses.size()) + " poses for " + std::to_string(expected_frames) +
                       " frames");
  }
  return poses;
}

RelativePose groundTruthRelativePose(const PlanarPose& query, const PlanarPose& candidate) {
  const cv::Matx33d wq = cameraToWorld(query), wc = cameraToWorld(candidate);
  RelativePose pose;
  pose.valid = true;
  pose.rotation = wq.t() * wc;
  const cv::Vec3d centre = wq.t() * cv::Vec3d(candidate.x - query.x, candidate.y - query.y, 0.0);
  const double norm = cv::norm(centre);
  if (norm > 0.0) pose.translation = centre / norm;
  return pose;
}

void PoseErrors::add(const RelativePose& estimate, const PlanarPose& query, const PlanarPose& candidate) {
  if (!estimate.valid) return;
  const RelativePose truth = groundTruthRelativePose(query, candidate);
  rotation_deg.push_back(rotationAngleDegrees(estimate.rotation, truth.rotation));
  if (std::hypot(candidate.x - query.x, candidate.y - query.y) >= min_baseline_m) {
    translation_deg.push_back(directionAngleDegrees(estimate.translation, truth.translation));
  }
}

}  // namespace mild
