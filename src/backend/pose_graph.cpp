#include "mild_lcd/backend/pose_graph.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <deque>
#include <limits>
#include <sstream>
#include <string>
#include <type_traits>

#include <ceres/ceres.h>

#include "mild_lcd/common/errors.hpp"

namespace mild::backend {
namespace {

template <class T>
T wrap(const T& a) {
  using std::atan2, std::cos, std::sin;
  return atan2(sin(a), cos(a));
}

// b's pose in a's frame minus the measurement, whitened. Odometry edges and metric loop edges.
struct RelativePoseCost {
  double dx, dy, dyaw, inv_translation, inv_rotation;
  template <class T>
  bool operator()(const T* a, const T* b, T* r) const {
    using std::cos, std::sin;
    const T c = cos(a[2]), s = sin(a[2]);
    const T ex = b[0] - a[0], ey = b[1] - a[1];
    r[0] = (c * ex + s * ey - dx) * inv_translation;
    r[1] = (-s * ex + c * ey - dy) * inv_translation;
    r[2] = wrap(b[2] - a[2] - T(dyaw)) * inv_rotation;
    return true;
  }
};

// A weak prior on a new chain's first keyframe: it ties the chain to the map until loops place it.
struct PriorCost {
  double x, y, yaw, inv_translation, inv_rotation;
  template <class T>
  bool operator()(const T* a, T* r) const {
    r[0] = (a[0] - T(x)) * inv_translation;
    r[1] = (a[1] - T(y)) * inv_translation;
    r[2] = wrap(a[2] - T(yaw)) * inv_rotation;
    return true;
  }
};

// A loop edge without scale: the relative yaw, and the candidate camera's centre on the measured
// ray from the query camera's centre (its distance from the ray; a penalty when behind).
struct BearingCost {
  double dyaw, ux, uy, inv_rotation, min_m, sigma;  // sigma: tan of the bearing's standard deviation
  double cam_x, cam_y;                              // camera centre in the base frame
  template <class T>
  bool operator()(const T* q, const T* k, T* r) const {
    using std::cos, std::sin, std::sqrt;
    const T cq = cos(q[2]), sq = sin(q[2]), ck = cos(k[2]), sk = sin(k[2]);
    // Camera centres in the map frame.
    const T qx = q[0] + cq * cam_x - sq * cam_y, qy = q[1] + sq * cam_x + cq * cam_y;
    const T kx = k[0] + ck * cam_x - sk * cam_y, ky = k[1] + sk * cam_x + ck * cam_y;
    // Their difference in the query base's orientation.
    const T wx = kx - qx, wy = ky - qy;
    const T dx = cq * wx + sq * wy, dy = -sq * wx + cq * wy;
    const T scale = sqrt(T(min_m * min_m) + (dx * dx + dy * dy) * T(sigma * sigma));
    const T along = ux * dx + uy * dy;
    r[0] = wrap(k[2] - q[2] - T(dyaw)) * inv_rotation;
    r[1] = (ux * dy - uy * dx) / scale;
    r[2] = along < T(0) ? along / scale : T(0);
    return true;
  }
};

double degrees(double d) { return d * kPi / 180.0; }

template <class T>
std::string text(const T& v) {
  if constexpr (std::is_same_v<T, std::string>) {
    return v;
  } else {
    std::ostringstream out;
    out << v;
    return out.str();
  }
}

}  // namespace

PoseGraphParams loadPoseGraphParams(const ParameterSource& source) {
  PoseGraphParams p;
  std::vector<std::string> known;
  PoseGraphParams::declare(p, [&](const char* name, auto& field, const Bounds&, const char*) {
    const std::string full = std::string(PoseGraphParams::kSection) + "/" + name;
    known.push_back(full);
    using T = std::decay_t<decltype(field)>;
    if constexpr (std::is_same_v<T, std::string>) {
      if (auto v = source.getString(full)) field = *v;
    } else if constexpr (std::is_same_v<T, int>) {
      if (auto v = source.getInt(full)) {
        if (*v < std::numeric_limits<int>::min() || *v > std::numeric_limits<int>::max()) {
          throw InvalidInput("parameter " + full + " is out of range: " + std::to_string(*v));
        }
        field = static_cast<int>(*v);
      }
    } else {
      if (auto v = source.getDouble(full)) field = *v;
    }
  });
  const std::string prefix = std::string(PoseGraphParams::kSection) + "/";
  for (const std::string& name : source.names()) {
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    if (std::find(known.begin(), known.end(), name) == known.end()) {
      std::string names;
      for (const std::string& k : known) names += (names.empty() ? "" : ", ") + k;
      throw InvalidInput("unknown parameter " + name + " (the pose graph's are " + names + ")");
    }
  }
  p.validate();
  return p;
}

std::string poseGraphParameterMarkdown(const std::string& prefix) {
  std::ostringstream out;
  const PoseGraphParams defaults;
  PoseGraphParams::declare(defaults, [&](const char* name, const auto& field, const Bounds& bounds, const char* doc) {
    out << "| `" << prefix << name << "` | `" << text(field) << "` | " << bounds.text() << " | " << doc << " |\n";
  });
  return out.str();
}

Extrinsics Extrinsics::forwardLooking() {
  Extrinsics e;
  e.rotation << 0.0, 0.0, 1.0,  //
      -1.0, 0.0, 0.0,           //
      0.0, -1.0, 0.0;
  e.translation.setZero();
  return e;
}

PlanarLoop planarLoop(const LoopMeasurement& loop, const Extrinsics& extrinsics) {
  PlanarLoop out;
  const Eigen::Matrix3d& rbc = extrinsics.rotation;
  const Eigen::Matrix3d rotation = rbc * loop.rotation.normalized().toRotationMatrix() * rbc.transpose();
  out.yaw = std::atan2(rotation(1, 0), rotation(0, 0));
  out.metric = loop.metric;
  if (!loop.translation.allFinite() || !std::isfinite(out.yaw)) return out;
  if (loop.metric) {
    const Eigen::Vector3d t = rbc * loop.translation + extrinsics.translation - rotation * extrinsics.translation;
    out.translation = t.head<2>();
    out.valid = true;
    return out;
  }
  const Eigen::Vector3d direction = rbc * loop.translation;
  const double norm = direction.norm(), horizontal = direction.head<2>().norm();
  // A baseline mostly along the vertical says nothing about the plane.
  if (!(norm > 0.0) || horizontal < 0.5 * norm) return out;
  out.bearing = direction.head<2>() / horizontal;
  out.valid = true;
  return out;
}

bool measurementIsValid(const LoopMeasurement& loop, double max_loop_distance) {
  const Eigen::Vector4d q = loop.rotation.coeffs();
  if (!q.allFinite() || std::abs(q.norm() - 1.0) > 0.1) return false;
  if (!loop.translation.allFinite()) return false;
  const double length = loop.translation.norm();
  return loop.metric ? length <= max_loop_distance : length > 1e-9;
}

bool extrinsicsAreValid(const Extrinsics& extrinsics, double max_distance) {
  if (!extrinsics.rotation.allFinite() || !extrinsics.translation.allFinite()) return false;
  const Eigen::Matrix3d r = extrinsics.rotation;
  if ((r.transpose() * r - Eigen::Matrix3d::Identity()).norm() > 1e-3 || std::abs(r.determinant() - 1.0) > 1e-3) {
    return false;
  }
  return extrinsics.translation.norm() <= max_distance;
}

struct PoseGraph2D::Impl {
  ceres::Problem problem;
  std::deque<std::array<double, 3>> estimates;  // stable addresses: Ceres keeps pointers to them
  std::vector<ceres::ResidualBlockId> loop_blocks;
  std::vector<ceres::CostFunction*> loop_costs;  // owned by the problem
};

PoseGraph2D::PoseGraph2D(const PoseGraphParams& params, const Extrinsics& extrinsics)
    : params_(params), extrinsics_(extrinsics), impl_(std::make_unique<Impl>()) {
  params_.validate();
  if (!extrinsicsAreValid(extrinsics_, params_.max_coordinate)) {
    throw InvalidInput("pose graph: the camera's extrinsics are not a rotation and a finite translation");
  }
}

PoseGraph2D::~PoseGraph2D() = default;

bool PoseGraph2D::acceptablePose(const Pose2& odometry) const {
  return std::isfinite(odometry.x) && std::isfinite(odometry.y) && std::isfinite(odometry.yaw) &&
         std::hypot(odometry.x, odometry.y) <= params_.max_coordinate;
}

void PoseGraph2D::addKeyframe(uint64_t id, const Pose2& odometry, bool new_chain) {
  if (index_.count(id)) throw InvalidInput("pose graph: keyframe " + std::to_string(id) + " is already in the graph");
  if (!acceptablePose(odometry)) {
    throw InvalidInput("pose graph: keyframe " + std::to_string(id) +
                       " has a non-finite or out-of-range odometry pose");
  }
  const size_t i = ids_.size();
  Pose2 start = odometry;
  if (i > 0) {
    // A new chain's odometry has another origin: where the robot is, the previous keyframe's
    // estimate is the best guess (it was there a keyframe ago).
    start = new_chain ? estimate(i - 1) : compose(estimate(i - 1), between(odometry_[i - 1], odometry));
  }
  ids_.push_back(id);
  index_.emplace(id, i);
  odometry_.push_back(odometry);
  impl_->estimates.push_back({start.x, start.y, wrapAngle(start.yaw)});
  double* block = impl_->estimates.back().data();
  impl_->problem.AddParameterBlock(block, 3);
  if (i == 0) {
    impl_->problem.SetParameterBlockConstant(block);  // the map's origin
    return;
  }
  if (new_chain) {
    // Where the robot is, only roughly known (1 m, 0.5 rad): loops to the earlier chain move it.
    impl_->problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<PriorCost, 3, 3>(new PriorCost{start.x, start.y, start.yaw, 1.0, 2.0}), nullptr,
        block);
    return;
  }
  const Pose2 delta = between(odometry_[i - 1], odometry);
  const double distance = std::hypot(delta.x, delta.y);
  const double sigma_t = std::max(params_.odometry_translation_min, params_.odometry_translation_sigma * distance);
  const double sigma_r =
      std::max(params_.odometry_rotation_min, params_.odometry_rotation_sigma * std::sqrt(distance) +
                                                  params_.odometry_rotation_per_rad * std::abs(delta.yaw));
  auto* cost = new ceres::AutoDiffCostFunction<RelativePoseCost, 3, 3, 3>(
      new RelativePoseCost{delta.x, delta.y, delta.yaw, 1.0 / sigma_t, 1.0 / sigma_r});
  impl_->problem.AddResidualBlock(cost, nullptr, impl_->estimates[i - 1].data(), block);
}

bool PoseGraph2D::addLoop(const LoopMeasurement& loop) {
  const auto q = index_.find(loop.query), c = index_.find(loop.candidate);
  if (q == index_.end() || c == index_.end() || q->second == c->second) return false;
  if (!measurementIsValid(loop, params_.max_loop_distance)) return false;
  const PlanarLoop planar = planarLoop(loop, extrinsics_);
  if (!planar.valid) return false;
  const double inv_rotation = 1.0 / degrees(params_.loop_rotation_sigma_deg);
  ceres::CostFunction* cost = nullptr;
  if (planar.metric) {
    cost = new ceres::AutoDiffCostFunction<RelativePoseCost, 3, 3, 3>(
        new RelativePoseCost{planar.translation.x(), planar.translation.y(), planar.yaw,
                             1.0 / params_.loop_translation_sigma, inv_rotation});
  } else {
    cost = new ceres::AutoDiffCostFunction<BearingCost, 3, 3, 3>(new BearingCost{
        planar.yaw, planar.bearing.x(), planar.bearing.y(), inv_rotation, params_.loop_bearing_min_m,
        std::tan(degrees(params_.loop_bearing_sigma_deg)), extrinsics_.translation.x(), extrinsics_.translation.y()});
  }
  ceres::LossFunction* loss = nullptr;
  if (params_.robust_loss == "cauchy") {
    loss = new ceres::CauchyLoss(params_.robust_scale);
  } else if (params_.robust_loss == "huber") {
    loss = new ceres::HuberLoss(params_.robust_scale);
  }
  const ceres::ResidualBlockId block = impl_->problem.AddResidualBlock(cost, loss, impl_->estimates[q->second].data(),
                                                                       impl_->estimates[c->second].data());
  impl_->loop_blocks.push_back(block);
  impl_->loop_costs.push_back(cost);
  Loop edge;
  edge.state.query = loop.query;
  edge.state.candidate = loop.candidate;
  edge.state.metric = planar.metric;
  edge.query = q->second;
  edge.candidate = c->second;
  edge.planar = planar;
  loops_.push_back(edge);
  return true;
}

void PoseGraph2D::truncateLoops(size_t count) {
  while (loops_.size() > count) {
    impl_->problem.RemoveResidualBlock(impl_->loop_blocks.back());
    impl_->loop_blocks.pop_back();
    impl_->loop_costs.pop_back();
    loops_.pop_back();
  }
}

UpdateStats PoseGraph2D::optimize() {
  UpdateStats stats;
  const auto start = std::chrono::steady_clock::now();
  if (ids_.size() > 1) {
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
    if (!ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE)) {
      options.sparse_linear_algebra_library_type = ceres::EIGEN_SPARSE;
    }
    options.max_num_iterations = params_.max_iterations;
    options.max_solver_time_in_seconds = params_.max_solver_seconds;
    options.num_threads = 1;
    options.logging_type = ceres::SILENT;
    const std::deque<std::array<double, 3>> before = impl_->estimates;  // values; the addresses stay
    ceres::Solver::Summary summary;
    ceres::Solve(options, &impl_->problem, &summary);
    stats.iterations = static_cast<int>(summary.iterations.size());
    stats.converged = summary.termination_type == ceres::CONVERGENCE;
    stats.initial_cost = summary.initial_cost;
    stats.final_cost = summary.final_cost;
    bool sane = summary.termination_type != ceres::FAILURE;
    for (const auto& e : impl_->estimates) {
      sane = sane && std::isfinite(e[0]) && std::isfinite(e[1]) && std::isfinite(e[2]) &&
             std::hypot(e[0], e[1]) <= params_.max_coordinate;
    }
    if (!sane) {
      for (size_t i = 0; i < before.size(); ++i) impl_->estimates[i] = before[i];
      stats.failed = true;
    }
    for (auto& e : impl_->estimates) e[2] = wrapAngle(e[2]);
  }
  for (size_t i = 0; i < loops_.size(); ++i) {
    Loop& loop = loops_[i];
    double r[3] = {0.0, 0.0, 0.0};
    const double* blocks[2] = {impl_->estimates[loop.query].data(), impl_->estimates[loop.candidate].data()};
    impl_->loop_costs[i]->Evaluate(blocks, r, nullptr);
    loop.state.residual = std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    loop.state.inlier = std::isfinite(loop.state.residual) && loop.state.residual <= params_.outlier_threshold;
  }
  stats.solve_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

Pose2 PoseGraph2D::estimate(size_t i) const {
  const auto& e = impl_->estimates[i];
  return {e[0], e[1], e[2]};
}

std::vector<Pose2> PoseGraph2D::estimates() const {
  std::vector<Pose2> out;
  out.reserve(ids_.size());
  for (size_t i = 0; i < ids_.size(); ++i) out.push_back(estimate(i));
  return out;
}

Pose2 PoseGraph2D::mapToOdom() const {
  if (ids_.empty()) return {};
  return compose(estimate(ids_.size() - 1), inverse(odometry_.back()));
}

std::vector<LoopEdgeState> PoseGraph2D::loops() const {
  std::vector<LoopEdgeState> out;
  out.reserve(loops_.size());
  for (const Loop& l : loops_) out.push_back(l.state);
  return out;
}

}  // namespace mild::backend
