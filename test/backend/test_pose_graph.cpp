// The example back-end's pose graph on trajectories with known truth: drift corrected by metric and
// by bearing-only loops, a wrong loop that the robust loss keeps from bending the map (and bends it
// without), the camera-to-base conversion of a loop, the alignment behind the trajectory error.

#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "backend_scenario.hpp"
#include "mild_lcd/backend/pose_graph.hpp"
#include "mild_lcd/backend/trajectory.hpp"
#include "mild_lcd/common/errors.hpp"

namespace mild::backend {
namespace {

struct GraphRun {
  double before = 0.0, after = 0.0;
  std::vector<LoopEdgeState> loops;
};

// Odometry with a heading bias, loops every 4th keyframe of laps 2 and 3 to the nearest of lap 1,
// plus `wrong` loops (query, candidate) carrying a right loop's measurement; optimised after each loop.
GraphRun runScenario(bool metric, const PoseGraphParams& params,
                     const std::vector<std::pair<size_t, size_t>>& wrong = {}) {
  const std::vector<Pose2> truth = threeLaps();
  const size_t lap = truth.size() / 3;  // about the first lap's length
  DriftModel drift;
  drift.heading_bias = 0.004;
  drift.seed = 7;
  const std::vector<Pose2> odometry = driftedOdometry(truth, drift);
  PoseGraph2D graph(params);
  for (size_t i = 0; i < truth.size(); ++i) {
    graph.addKeyframe(100 + i, odometry[i]);
    bool added = false;
    if (i >= lap + 10 && i % 4 == 0) {
      const size_t c = nearestInFirstLap(truth, i, lap);
      added |= graph.addLoop(measure(truth[i], truth[c], 100 + i, 100 + c, metric));
    }
    for (const auto& [q, c] : wrong) {
      if (q != i) continue;
      // A right-looking measurement (the one the nearest place would give) on the wrong pair.
      const size_t near = nearestInFirstLap(truth, i, lap);
      LoopMeasurement m = measure(truth[i], truth[near], 100 + q, 100 + c, metric);
      added |= graph.addLoop(m);
    }
    if (added) graph.optimize();
  }
  graph.optimize();
  GraphRun r;
  r.before = absoluteTrajectoryError(odometry, truth);
  r.after = absoluteTrajectoryError(graph.estimates(), truth);
  r.loops = graph.loops();
  return r;
}

TEST(PoseGraph, MetricLoopsCorrectDrift) {
  const GraphRun r = runScenario(true, PoseGraphParams{});
  EXPECT_GT(r.before, 0.5);
  EXPECT_LT(r.after, 0.3 * r.before) << "before " << r.before << " after " << r.after;
  for (const LoopEdgeState& l : r.loops) EXPECT_TRUE(l.inlier) << l.query << " -> " << l.candidate;
}

TEST(PoseGraph, BearingOnlyLoopsFixRotationAndDirection) {
  const GraphRun r = runScenario(false, PoseGraphParams{});
  EXPECT_GT(r.before, 0.5);
  EXPECT_LT(r.after, 0.3 * r.before) << "before " << r.before << " after " << r.after;
  size_t inliers = 0;
  for (const LoopEdgeState& l : r.loops) inliers += l.inlier;
  EXPECT_EQ(inliers, r.loops.size());
}

TEST(PoseGraph, OneWrongLoopDoesNotBendTheMap) {
  // Keyframe 250 (third lap) "closes" with keyframe 20 (first lap, across the rectangle).
  const std::vector<std::pair<size_t, size_t>> wrong = {{250, 20}};
  for (bool metric : {true, false}) {
    const GraphRun clean = runScenario(metric, PoseGraphParams{});
    const GraphRun robust = runScenario(metric, PoseGraphParams{}, wrong);
    EXPECT_LT(robust.after, 0.3 * robust.before);
    EXPECT_LT(robust.after, 1.1 * clean.after + 0.01) << "metric " << metric;
    bool flagged = false;
    for (const LoopEdgeState& l : robust.loops) {
      if (l.query == 350 && l.candidate == 120) flagged = !l.inlier;
    }
    EXPECT_TRUE(flagged) << "the wrong loop is reported rejected (metric " << metric << ")";
    // Plain least squares: the same wrong loop bends the map (what the loss is for).
    PoseGraphParams plain;
    plain.robust_loss = "none";
    const GraphRun bent = runScenario(metric, plain, wrong);
    std::printf("metric %d: ATE odometry %.3f, clean %.3f, one wrong loop %.3f, without the loss %.3f\n", metric,
                clean.before, clean.after, robust.after, bent.after);
    EXPECT_GT(bent.after, 1.5 * clean.after) << "metric " << metric;
  }
}

TEST(PoseGraph, LoopInCameraFrameBecomesThePlanarEdge) {
  Extrinsics e = Extrinsics::forwardLooking();
  e.translation = Eigen::Vector3d(0.3, -0.1, 1.2);  // ahead, to the right, up
  const Pose2 q{2.0, 1.0, 0.4}, c{3.5, 2.5, 1.1};
  const Pose2 truth = between(q, c);
  const PlanarLoop metric = planarLoop(measure(q, c, 1, 2, true, e), e);
  ASSERT_TRUE(metric.valid);
  EXPECT_NEAR(metric.yaw, truth.yaw, 1e-9);
  EXPECT_NEAR(metric.translation.x(), truth.x, 1e-9);
  EXPECT_NEAR(metric.translation.y(), truth.y, 1e-9);
  const PlanarLoop bearing = planarLoop(measure(q, c, 1, 2, false, e), e);
  ASSERT_TRUE(bearing.valid);
  EXPECT_FALSE(bearing.metric);
  // Camera centre to camera centre, in the query base's orientation.
  const Pose2 cam{e.translation.x(), e.translation.y(), 0.0};
  const Pose2 qc = compose(q, cam), cc = compose(c, cam);
  const double bx = std::cos(q.yaw) * (cc.x - qc.x) + std::sin(q.yaw) * (cc.y - qc.y);
  const double by = -std::sin(q.yaw) * (cc.x - qc.x) + std::cos(q.yaw) * (cc.y - qc.y);
  EXPECT_NEAR(bearing.bearing.x(), bx / std::hypot(bx, by), 1e-9);
  EXPECT_NEAR(bearing.bearing.y(), by / std::hypot(bx, by), 1e-9);
  // A baseline straight up says nothing about the plane.
  LoopMeasurement up;
  up.translation = Eigen::Vector3d(0.0, -1.0, 0.0);  // camera y points down
  EXPECT_FALSE(planarLoop(up, Extrinsics::forwardLooking()).valid);
}

TEST(PoseGraph, RejectsWhatItCannotUse) {
  PoseGraph2D graph;
  graph.addKeyframe(5, {0, 0, 0});
  EXPECT_THROW(graph.addKeyframe(5, {1, 0, 0}), InvalidInput);
  EXPECT_THROW(graph.addKeyframe(6, {NAN, 0, 0}), InvalidInput);
  graph.addKeyframe(6, {1, 0, 0});
  EXPECT_FALSE(graph.addLoop(measure({0, 0, 0}, {1, 0, 0}, 6, 7, true)));  // 7 unknown
  EXPECT_FALSE(graph.addLoop(measure({0, 0, 0}, {1, 0, 0}, 6, 6, true)));  // itself
  EXPECT_TRUE(graph.addLoop(measure({0, 0, 0}, {1, 0, 0}, 6, 5, true)));
  PoseGraphParams bad;
  bad.robust_loss = "tukey";
  EXPECT_THROW(PoseGraph2D{bad}, InvalidInput);
}

TEST(PoseGraph, MapToOdomIsTheCorrectionOfTheNewestKeyframe) {
  // A drift far beyond the odometry's standard deviations, which the robust loss would refuse.
  PoseGraphParams plain;
  plain.robust_loss = "none";
  plain.loop_translation_sigma = 0.001;  // a loop far more certain than the odometry
  plain.loop_rotation_sigma_deg = 0.01;
  PoseGraph2D graph(plain);
  graph.addKeyframe(0, {0, 0, 0});
  graph.addKeyframe(1, {1, 0, 0});
  graph.addKeyframe(2, {2, 0, 0.1});
  // Keyframe 2 is where keyframe 0 is, rotated as it: the odometry drifted 2 m and 0.1 rad.
  ASSERT_TRUE(graph.addLoop(measure({0, 0, 0}, {0, 0, 0}, 2, 0, true)));
  graph.optimize();
  const Pose2 latest = graph.estimate(2);
  const Pose2 corrected = compose(graph.mapToOdom(), graph.odometry(2));
  EXPECT_NEAR(corrected.x, latest.x, 1e-9);
  EXPECT_NEAR(corrected.y, latest.y, 1e-9);
  EXPECT_NEAR(latest.x, 0.0, 0.1);
  EXPECT_NEAR(latest.yaw, 0.0, 0.05);
}

TEST(Trajectory, AlignmentRemovesARigidMotion) {
  const std::vector<Pose2> truth = threeLaps();
  std::vector<Pose2> moved;
  const Pose2 motion{3.0, -2.0, 0.7};
  for (const Pose2& p : truth) moved.push_back(compose(motion, p));
  EXPECT_NEAR(absoluteTrajectoryError(moved, truth), 0.0, 1e-9);
  std::vector<Pose2> shifted = truth;
  shifted[0].x += 1.0;  // one pose 1 m off
  const double ate = absoluteTrajectoryError(shifted, truth);
  EXPECT_GT(ate, 0.0);
  EXPECT_LT(ate, 1.0 / std::sqrt(static_cast<double>(truth.size())) + 1e-9);
  EXPECT_THROW(absoluteTrajectoryError(truth, {}), InvalidInput);
}

TEST(Trajectory, DriftFollowsTheModelAndTheSeed) {
  const std::vector<Pose2> truth = threeLaps();
  DriftModel model;
  model.translation_noise = 0.0;
  model.heading_random_walk = 0.0;
  model.scale_error = 0.02;
  const std::vector<Pose2> scaled = driftedOdometry(truth, model);
  EXPECT_NEAR(pathLength(scaled), 1.02 * pathLength(truth), 1e-6);
  DriftModel noisy;
  noisy.seed = 3;
  const auto a = driftedOdometry(truth, noisy), b = driftedOdometry(truth, noisy);
  noisy.seed = 4;
  const auto c = driftedOdometry(truth, noisy);
  EXPECT_EQ(a.back().x, b.back().x);
  EXPECT_NE(a.back().x, c.back().x);
  EXPECT_EQ(a.front().x, truth.front().x);
}

}  // namespace
}  // namespace mild::backend
