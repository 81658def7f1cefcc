#pragma once

// An example back-end that consumes mild_lcd's loop closures: a planar (SE(2)) pose graph of the
// keyframes, odometry edges between consecutive keyframes and loop edges from LoopClosure
// candidates, solved with Ceres. ROS-free; the pose-graph nodelet (src/ros/nodelets/pose_graph_nodelet.cpp)
// only feeds it. An example of consuming the interface, not a SLAM system: no map, no re-localisation,
// one trajectory.
//
// Loop edges. A candidate's relative pose is the candidate camera's pose in the query camera's
// optical frame (LoopCandidate.relative_rotation / relative_translation). With the camera's
// mounting on the robot (Extrinsics, tf base -> camera) it becomes the candidate base's pose in
// the query base's frame; the graph keeps its planar part (yaw from the rotation, x and y of the
// translation: the bench and a ground robot move on a plane, and the camera's small pitch and roll
// are dropped).
// - metric translation (the query keyframe had depth): a full SE(2) edge.
// - unit translation (no depth): rotation plus a bearing: the candidate camera's centre must lie on
//   the ray from the query camera's centre along the measured direction, expressed as its distance
//   from the ray in metres over sqrt(bearing_min_m^2 + (baseline x sigma)^2) (so a short baseline,
//   whose direction the images barely fix, weighs little, and the residual is defined at zero
//   baseline) plus a penalty when it lies behind the query camera. The length along the ray is left
//   to the odometry.
//
// Robustness. Each loop edge (rotation and translation together) goes through a Cauchy loss
// (robust_loss): a wrong loop's residual stays large, its weight falls as 1 / (1 + r^2 / c^2), and
// the odometry chain holds the map. docs/pose_graph.md measures it against no loss with 5 % of the
// loops replaced by wrong ones.

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "mild_lcd/backend/pose2.hpp"
#include "mild_lcd/params/parameter_source.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild::backend {

struct PoseGraphParams {
  double odometry_translation_sigma = 0.02;
  double odometry_translation_min = 0.005;
  double odometry_rotation_sigma = 0.01;
  double odometry_rotation_min = 0.001;
  double odometry_rotation_per_rad = 0.0;
  double loop_rotation_sigma_deg = 3.0;
  double loop_translation_sigma = 0.1;
  double loop_bearing_sigma_deg = 15.0;
  double loop_bearing_min_m = 0.3;
  std::string robust_loss = "cauchy";
  double robust_scale = 2.0;
  double outlier_threshold = 3.0;
  int max_iterations = 30;
  double max_solver_seconds = 0.2;
  double max_coordinate = 1e5;
  double max_loop_distance = 100.0;

  static constexpr const char* kSection = "graph";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("odometry_translation_sigma", p.odometry_translation_sigma, Bounds::above(0),
      "Odometry edges: standard deviation of each translation component per metre travelled between the two "
      "keyframes (metres per metre, > 0).");
    v("odometry_translation_min", p.odometry_translation_min, Bounds::above(0),
      "Odometry edges: least translation standard deviation, for a robot standing still (metres, > 0).");
    v("odometry_rotation_sigma", p.odometry_rotation_sigma, Bounds::above(0),
      "Odometry edges: heading standard deviation per square root of the metres travelled, a heading random walk "
      "(radians per square-root metre, > 0).");
    v("odometry_rotation_min", p.odometry_rotation_min, Bounds::above(0),
      "Odometry edges: least heading standard deviation (radians, > 0).");
    v("odometry_rotation_per_rad", p.odometry_rotation_per_rad, Bounds::atLeast(0),
      "Odometry edges: heading standard deviation added per radian turned between the two keyframes (radians per "
      "radian, >= 0).");
    v("loop_rotation_sigma_deg", p.loop_rotation_sigma_deg, Bounds::above(0),
      "Loop edges: standard deviation of the relative yaw (degrees, > 0).");
    v("loop_translation_sigma", p.loop_translation_sigma, Bounds::above(0),
      "Metric loop edges (the query keyframe had depth): standard deviation of each translation component (metres, "
      "> 0).");
    v("loop_bearing_sigma_deg", p.loop_bearing_sigma_deg, Bounds::above(0),
      "Bearing loop edges (no depth): standard deviation of the baseline's direction (degrees, > 0).");
    v("loop_bearing_min_m", p.loop_bearing_min_m, Bounds::above(0),
      "Bearing loop edges: the distance from the ray is divided by sqrt(this^2 + (baseline x sigma)^2), so that "
      "short baselines weigh little (metres, > 0).");
    v("robust_loss", p.robust_loss, Bounds::oneOf({"cauchy", "huber", "none"}),
      "Loss on each loop edge's whitened residual, cauchy, huber or none (plain least squares).");
    v("robust_scale", p.robust_scale, Bounds::above(0),
      "Scale c of the loss: with cauchy a loop edge whose whitened residual is r weighs 1 / (1 + r^2 / c^2) "
      "(standard deviations, > 0).");
    v("outlier_threshold", p.outlier_threshold, Bounds::above(0),
      "A loop edge whose whitened residual exceeds this after a solve is reported rejected, and stays in the graph "
      "down-weighted by the loss (standard deviations, > 0).");
    v("max_iterations", p.max_iterations, Bounds::in(1, 1000),
      "Solver iterations per update, each update starting from the previous solution (iterations, 1 to 1000).");
    v("max_solver_seconds", p.max_solver_seconds, Bounds::above(0),
      "Wall time of one update, after which the solver stops with its best solution so far (seconds, > 0).");
    v("max_coordinate", p.max_coordinate, Bounds::above(0),
      "Odometry poses and solved estimates farther than this from the origin are refused (metres, > 0).");
    v("max_loop_distance", p.max_loop_distance, Bounds::above(0),
      "Metric loop measurements whose translation is longer than this are refused (metres, > 0).");
  }
  void validate() const { validateDeclared(*this); }
};

// Reads "graph/<name>" for every declared parameter the source holds (absent ones keep their
// defaults), type-checked; rejects unknown names under graph/ and validates. Throws InvalidInput
// naming the parameter.
PoseGraphParams loadPoseGraphParams(const ParameterSource& source);
// The declared parameters as a Markdown table (name with prefix, default, range, meaning).
std::string poseGraphParameterMarkdown(const std::string& prefix = "~graph/");

// How the camera sits on the robot: the camera's optical frame (x right, y down, z forward) in the
// base frame (x forward, y left, z up), as tf's base -> camera transform.
struct Extrinsics {
  Eigen::Matrix3d rotation;     // camera axes in base coordinates (columns)
  Eigen::Vector3d translation;  // camera centre in the base frame, metres
  // A camera at the base's origin looking along the base's x axis: rotation columns (0,-1,0),
  // (0,0,-1), (1,0,0).
  static Extrinsics forwardLooking();
};

// A loop closure as LoopCandidate carries it: the candidate camera's pose in the query camera's
// optical frame.
struct LoopMeasurement {
  uint64_t query = 0;
  uint64_t candidate = 0;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  // candidate camera -> query camera
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();         // candidate centre in the query camera
  bool metric = false;  // translation in metres; otherwise only its direction counts
};

// The planar loop edge a measurement gives, in the query base's frame.
struct PlanarLoop {
  double yaw = 0.0;                                       // candidate base yaw relative to the query base
  Eigen::Vector2d translation = Eigen::Vector2d::Zero();  // metric: candidate base origin
  Eigen::Vector2d bearing = Eigen::Vector2d::Zero();      // unit: direction query camera -> candidate camera
  bool metric = false;
  bool valid = false;  // false for a non-metric translation with (nearly) no horizontal part
};
PlanarLoop planarLoop(const LoopMeasurement& loop, const Extrinsics& extrinsics);
// A measurement the graph can take: finite, a rotation quaternion of norm near 1, a metric
// translation no longer than max_loop_distance, a unit translation that is not zero.
bool measurementIsValid(const LoopMeasurement& loop, double max_loop_distance);
// Extrinsics the graph can take: a rotation (orthonormal, det 1) and a finite translation no
// longer than max_distance.
bool extrinsicsAreValid(const Extrinsics& extrinsics, double max_distance);

struct LoopEdgeState {
  uint64_t query = 0, candidate = 0;
  bool metric = false;
  double residual = 0.0;  // whitened residual norm at the current solution, standard deviations
  bool inlier = true;     // residual <= outlier_threshold
};

struct UpdateStats {
  double solve_ms = 0.0;
  int iterations = 0;
  bool converged = false;
  double initial_cost = 0.0, final_cost = 0.0;
  // The solve failed or left a non-finite or out-of-range estimate: the estimates are those from
  // before it, and the next update starts from them again.
  bool failed = false;
};

class PoseGraph2D {
 public:
  explicit PoseGraph2D(const PoseGraphParams& params = {}, const Extrinsics& extrinsics = Extrinsics::forwardLooking());
  ~PoseGraph2D();
  PoseGraph2D(const PoseGraph2D&) = delete;
  PoseGraph2D& operator=(const PoseGraph2D&) = delete;

  // Appends a keyframe with its odometry pose (odom frame). Its estimate starts as the previous
  // keyframe's estimate moved by the odometry between them; the first keyframe is the map's origin
  // (fixed at its odometry pose: map and odom coincide until a loop). new_chain: no odometry edge to
  // the previous keyframe (the odometry restarted with another origin); the keyframe is held at the
  // previous keyframe's estimate (the best guess of where the robot is) by a weak prior (1 m,
  // 0.5 rad) that loops to earlier keyframes override. Throws InvalidInput for
  // an id already in the graph or a pose that is not finite or farther than max_coordinate.
  void addKeyframe(uint64_t id, const Pose2& odometry, bool new_chain = false);
  // Whether addKeyframe would take this odometry pose (finite, within max_coordinate).
  bool acceptablePose(const Pose2& odometry) const;
  bool contains(uint64_t id) const { return index_.count(id) != 0; }
  size_t size() const { return ids_.size(); }

  // Adds a loop edge between two keyframes of the graph. Returns false (adding nothing) when either
  // is unknown, they are the same, or the measurement has no usable planar part: use
  // measurementIsValid first to tell an absurd measurement from an unknown keyframe.
  bool addLoop(const LoopMeasurement& loop);
  size_t loopCount() const { return loops_.size(); }
  // Removes the loops added after the first `count` (after a failed solve: the graph goes back to
  // what solved).
  void truncateLoops(size_t count);

  // Re-solves from the current estimate, bounded by max_iterations and max_solver_seconds, then
  // refreshes every loop edge's residual and inlier flag.
  UpdateStats optimize();

  const std::vector<uint64_t>& ids() const { return ids_; }
  Pose2 estimate(size_t i) const;
  Pose2 odometry(size_t i) const { return odometry_[i]; }
  std::vector<Pose2> estimates() const;
  // map -> odom: the newest keyframe's estimate times the inverse of its odometry pose (REP 105).
  Pose2 mapToOdom() const;
  std::vector<LoopEdgeState> loops() const;
  const PoseGraphParams& params() const { return params_; }

 private:
  struct Impl;
  PoseGraphParams params_;
  Extrinsics extrinsics_;
  std::vector<uint64_t> ids_;
  std::unordered_map<uint64_t, size_t> index_;
  std::vector<Pose2> odometry_;
  struct Loop {
    LoopEdgeState state;
    size_t query = 0, candidate = 0;
    PlanarLoop planar;
  };
  std::vector<Loop> loops_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace mild::backend
