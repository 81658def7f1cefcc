// The example back-end's boundary (backend/keyframe_admission.hpp, graph_builder.hpp) under hostile
// input, one test per input kind (odometry, tf, loop measurement, stamp) with non-finite and absurd
// finite values: nothing throws, the value is refused and counted, the trajectory and map -> odom
// stay finite and no worse than the raw odometry. Then ids (a detector reset, duplicates, another
// robot), waiting bounded in time and count, and a failed solve.

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "backend_scenario.hpp"
#include "mild_lcd/backend/graph_builder.hpp"
#include "mild_lcd/backend/keyframe_admission.hpp"
#include "mild_lcd/backend/trajectory.hpp"

namespace mild::backend {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int64_t kSecond = 1000000000;
constexpr int64_t kStart = 1000 * kSecond;
constexpr int64_t kPeriod = kSecond / 10;  // keyframes at 10 Hz

Eigen::Quaterniond yawQuaternion(double yaw) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
}

// Three laps with drifted odometry; keyframe i at kStart + i kPeriod with its odometry sample, and
// metric loops from every 4th keyframe of laps 2 and 3 to the nearest of lap 1. Hooks let a test
// spoil one input; the back-end is fed as the nodelet feeds it (odometry and keyframes through the
// waiting room, batches of what is ready into the builder).
struct Replay {
  std::vector<Pose2> truth = threeLaps();
  std::vector<Pose2> odometry;
  size_t lap = truth.size() / 3;
  AdmissionParams admission_params;
  PoseGraphParams graph_params;
  BuilderParams builder_params;
  std::function<void(size_t, Eigen::Vector3d&, Eigen::Quaterniond&)> spoil_odometry;
  std::function<void(size_t, KeyframeInput&)> spoil_keyframe;
  KeyframeAdmission::PoseAt pose_at;  // tf instead of the odometry topic
  Extrinsics extrinsics = Extrinsics::forwardLooking();
  // Results.
  BackendCounters counters;
  std::vector<Pose2> estimates, graph_odometry;
  std::vector<LoopEdgeState> loops;
  Pose2 map_to_odom;
  double ate_raw = 0.0, ate_corrected = 0.0;

  Replay() {
    DriftModel drift;
    drift.heading_bias = 0.004;
    drift.seed = 7;
    odometry = driftedOdometry(truth, drift);
  }

  KeyframeInput keyframe(size_t i) const {
    KeyframeInput k;
    k.stamp_ns = kStart + static_cast<int64_t>(i) * kPeriod;
    k.id = i;
    k.camera_frame = "camera";
    if (i >= lap + 10 && i % 4 == 0) {
      const size_t c = nearestInFirstLap(truth, i, lap);
      LoopInput loop;
      loop.candidate = c;
      loop.measurement = measure(truth[i], truth[c], i, c, true);
      k.loops.push_back(loop);
    }
    return k;
  }

  void run() {
    KeyframeAdmission admission(admission_params);
    GraphBuilder builder(graph_params, builder_params);
    builder.start(extrinsics, 10.0);
    for (size_t i = 0; i < truth.size(); ++i) {
      const int64_t stamp = kStart + static_cast<int64_t>(i) * kPeriod;
      Eigen::Vector3d position(odometry[i].x, odometry[i].y, 0.0);
      Eigen::Quaterniond orientation = yawQuaternion(odometry[i].yaw);
      if (spoil_odometry) spoil_odometry(i, position, orientation);
      admission.addOdometry(stamp, position, orientation);
      KeyframeInput k = keyframe(i);
      if (spoil_keyframe) spoil_keyframe(i, k);
      admission.addKeyframe(k, stamp);
      builder.add(admission.takeReady(stamp, pose_at));
    }
    // Past every wait: what still waits is given up.
    builder.add(admission.takeReady(kStart + static_cast<int64_t>(truth.size()) * kPeriod + 60 * kSecond, pose_at));
    counters = {};
    admission.addCountersTo(counters);
    builder.addCountersTo(counters);
    estimates = builder.graph().estimates();
    map_to_odom = builder.graph().mapToOdom();
    loops = builder.graph().loops();
    std::vector<Pose2> truth_kept, raw_kept;
    for (size_t n = 0; n < estimates.size(); ++n) {
      const size_t i = static_cast<size_t>((builder.stamps()[n] - kStart) / kPeriod);
      truth_kept.push_back(truth[i]);
      raw_kept.push_back(odometry[i]);
      graph_odometry.push_back(builder.graph().odometry(n));
    }
    ate_raw = absoluteTrajectoryError(raw_kept, truth_kept);
    ate_corrected = absoluteTrajectoryError(estimates, truth_kept);
  }

  void expectSaneResult() const {
    for (const Pose2& p : estimates) {
      ASSERT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.yaw));
    }
    EXPECT_TRUE(std::isfinite(map_to_odom.x) && std::isfinite(map_to_odom.y) && std::isfinite(map_to_odom.yaw));
    EXPECT_LT(ate_corrected, ate_raw) << "the corrected trajectory is no worse than the raw odometry";
    EXPECT_EQ(counters.received, counters.in_graph + counters.waiting + counters.dropped());
    EXPECT_EQ(counters.solves_failed, 0u);
  }
};

TEST(BackendInputs, CleanReplayCorrectsTheDriftAndAccountsForEveryKeyframe) {
  Replay r;
  r.run();
  r.expectSaneResult();
  EXPECT_EQ(r.counters.in_graph, r.truth.size());
  EXPECT_EQ(r.counters.dropped(), 0u);
  EXPECT_LT(r.ate_corrected, 0.3 * r.ate_raw);
  EXPECT_GT(r.counters.loops_kept, 20u);
  EXPECT_EQ(r.counters.chains, 1u);
}

TEST(BackendInputs, OdometryNonFiniteOrAbsurdIsRefusedAndCounted) {
  Replay r;
  r.spoil_odometry = [](size_t i, Eigen::Vector3d& p, Eigen::Quaterniond& q) {
    if (i == 50) p.x() = kNaN;
    if (i == 60) q = Eigen::Quaterniond(kInf, 0, 0, 0);
    if (i == 70) p.y() = 1e300;                       // beyond graph/max_coordinate
    if (i == 80) q = Eigen::Quaterniond(0, 0, 0, 0);  // not a rotation
    if (i == 90) p.x() += 5000.0;                     // a finite spike: the keyframe jumps
  };
  r.run();
  ASSERT_NO_FATAL_FAILURE(r.expectSaneResult());
  EXPECT_EQ(r.counters.odometry_rejected, 4u);
  EXPECT_EQ(r.counters.dropped_odometry_jump, 1u) << "the 5 km spike";
  // Keyframes 50, 60, 70, 80 take the pose interpolated between the samples around them (their
  // own was refused); only the spike's keyframe is lost.
  EXPECT_EQ(r.counters.in_graph, r.truth.size() - 1);
  EXPECT_LT(r.ate_corrected, 0.3 * r.ate_raw);
}

TEST(BackendInputs, OdometryThatRestartsStartsANewChainInsteadOfDroppingEverything) {
  Replay r;
  // From keyframe 100 on, the odometry is 1 km away (a restarted odometry with another origin).
  r.spoil_odometry = [](size_t i, Eigen::Vector3d& p, Eigen::Quaterniond&) {
    if (i >= 100) p.x() += 1000.0;
  };
  r.run();
  ASSERT_NO_FATAL_FAILURE(r.expectSaneResult());
  EXPECT_EQ(r.counters.dropped_odometry_jump, 2u) << "two are taken for spikes, the third starts a chain";
  EXPECT_EQ(r.counters.chains, 2u);
  EXPECT_EQ(r.counters.in_graph, r.truth.size() - 2);
}

TEST(BackendInputs, TfPoseNonFiniteOrAbsurdIsRefusedAndCounted) {
  Replay r;
  r.pose_at = [&r](int64_t stamp) -> std::optional<Pose2> {
    const size_t i = static_cast<size_t>((stamp - kStart) / kPeriod);
    if (i == 40) return Pose2{kNaN, 0.0, 0.0};
    if (i == 41) return Pose2{0.0, 0.0, kInf};
    if (i == 42) return Pose2{1e300, 0.0, 0.0};
    return r.odometry[i];
  };
  r.run();
  ASSERT_NO_FATAL_FAILURE(r.expectSaneResult());
  EXPECT_EQ(r.counters.tf_rejected, 3u);
  EXPECT_EQ(r.counters.dropped_invalid_pose, 3u);
  EXPECT_EQ(r.counters.in_graph, r.truth.size() - 3);
}

TEST(BackendInputs, CameraMountingNonFiniteOrAbsurdFallsBackAndIsCounted) {
  for (const Eigen::Vector3d& t :
       {Eigen::Vector3d(kNaN, 0, 0), Eigen::Vector3d(1e300, 0, 0), Eigen::Vector3d(0, 50, 0)}) {
    GraphBuilder builder(PoseGraphParams{}, BuilderParams{});
    Extrinsics e = Extrinsics::forwardLooking();
    e.translation = t;
    EXPECT_FALSE(builder.start(e, 10.0));
    BackendCounters c;
    builder.addCountersTo(c);
    EXPECT_EQ(c.tf_rejected, 1u);
    EXPECT_TRUE(builder.started()) << "a forward-looking camera at the base's origin is used instead";
  }
  GraphBuilder rotated(PoseGraphParams{}, BuilderParams{});
  Extrinsics e = Extrinsics::forwardLooking();
  e.rotation *= 2.0;  // not a rotation
  EXPECT_FALSE(rotated.start(e, 10.0));
}

TEST(BackendInputs, LoopMeasurementNonFiniteOrAbsurdIsRefusedAndCounted) {
  Replay r;
  size_t spoiled = 0;
  r.spoil_keyframe = [&spoiled](size_t, KeyframeInput& k) {
    if (k.loops.empty() || spoiled >= 5) return;
    LoopMeasurement& m = k.loops[0].measurement;
    switch (spoiled++) {
      case 0:
        m.translation.x() = kNaN;
        break;
      case 1:
        m.translation = Eigen::Vector3d(0, 0, 1e200);
        break;  // a metric loop 1e200 m long
      case 2:
        m.rotation = Eigen::Quaterniond(kNaN, 0, 0, 0);
        break;
      case 3:
        m.rotation = Eigen::Quaterniond(0, 0, 0, 0);
        break;
      case 4:
        m.metric = false, m.translation.setZero();
        break;
    }
  };
  r.run();
  ASSERT_NO_FATAL_FAILURE(r.expectSaneResult());
  EXPECT_EQ(r.counters.loops_refused, 5u);
  EXPECT_EQ(r.counters.in_graph, r.truth.size()) << "a refused loop loses no keyframe";
  EXPECT_LT(r.ate_corrected, 0.3 * r.ate_raw) << "every later loop is still used";
}

// A LoopClosure carrying a hundred thousand copies of one loop once made as many residuals in every
// solve, and the waiting room bounds keyframes, not their size: one loop per candidate is kept, at
// most kMaxLoopsPerKeyframe, the rest refused and counted.
TEST(BackendInputs, ALoopRepeatedOrPastTheBoundInOneKeyframeIsRefusedAndCounted) {
  Replay r;
  size_t spoiled = 0;
  r.spoil_keyframe = [&spoiled](size_t, KeyframeInput& k) {
    if (k.loops.empty() || spoiled++ > 0) return;
    const LoopInput loop = k.loops.front();
    k.loops.assign(100000, loop);          // copies of the one loop
    for (uint64_t n = 0; n < 1000; ++n) {  // and loops to a thousand keyframes the graph does not hold
      LoopInput other = loop;
      other.candidate = 1000000000 + n;
      k.loops.push_back(other);
    }
  };
  r.run();
  ASSERT_NO_FATAL_FAILURE(r.expectSaneResult());
  EXPECT_EQ(r.counters.loops_refused, 100000u + 1000u - KeyframeAdmission::kMaxLoopsPerKeyframe);
  EXPECT_EQ(r.counters.loops_skipped, KeyframeAdmission::kMaxLoopsPerKeyframe - 1) << "the kept ones find no keyframe";
  EXPECT_EQ(r.counters.in_graph, r.truth.size());
  Replay clean;
  clean.run();
  EXPECT_EQ(r.loops.size(), clean.loops.size()) << "one loop of the copies, as without them";
}

TEST(BackendInputs, KeyframeStampedAnHourAheadDoesNotHoldBackTheOnesAfterIt) {
  Replay r;
  r.spoil_keyframe = [](size_t i, KeyframeInput& k) {
    if (i == 30) k.stamp_ns += 3600 * kSecond;
  };
  r.run();
  ASSERT_NO_FATAL_FAILURE(r.expectSaneResult());
  EXPECT_EQ(r.counters.dropped_future_stamp, 1u);
  EXPECT_EQ(r.counters.in_graph, r.truth.size() - 1) << "every keyframe after it is in the graph";
  EXPECT_EQ(r.counters.waiting, 0u);
}

TEST(BackendInputs, KeyframesWaitAtMostOdometryWaitAndAtMostMaxWaiting) {
  AdmissionParams params;
  params.odometry_wait = 2.0;
  params.max_waiting = 10;
  KeyframeAdmission admission(params);
  admission.addOdometry(kStart, Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity());
  // Twelve keyframes after the last odometry: two too many wait; the rest give up after 2 s.
  for (int i = 1; i <= 12; ++i) {
    KeyframeInput k;
    k.id = static_cast<uint64_t>(i);
    k.stamp_ns = kStart + i * kPeriod;
    admission.addKeyframe(k, kStart + i * kPeriod);
  }
  EXPECT_TRUE(admission.takeReady(kStart + 2 * kSecond).empty());
  BackendCounters c;
  admission.addCountersTo(c);
  EXPECT_EQ(c.dropped_queue_full, 2u);
  EXPECT_EQ(c.waiting, 10u);
  EXPECT_TRUE(admission.takeReady(kStart + 5 * kSecond).empty());
  c = {};
  admission.addCountersTo(c);
  EXPECT_EQ(c.dropped_no_odometry, 10u);
  EXPECT_EQ(c.received, c.waiting + c.dropped());

  // The clock going back (a bag played again) restarts the wait instead of waiting forever or
  // giving up at once.
  KeyframeInput late;
  late.stamp_ns = kStart + 100 * kSecond;
  admission.addKeyframe(late, kStart + 100 * kSecond);
  EXPECT_TRUE(admission.takeReady(kStart).empty());
  c = {};
  admission.addCountersTo(c);
  EXPECT_EQ(c.waiting, 1u);
  EXPECT_TRUE(admission.takeReady(kStart + 3 * kSecond).empty());
  c = {};
  admission.addCountersTo(c);
  EXPECT_EQ(c.waiting, 0u);
  EXPECT_EQ(c.dropped_no_odometry, 11u);
}

TEST(BackendInputs, DetectorResetStartsANewChainAndNoLoopCrossesSessionsThroughAReusedId) {
  Replay r;
  // After keyframe 120 the detector is reset: ids start again at 0 in session 0, and its candidates
  // are the new run's keyframes, named by the new ids (id 5 is the new run's keyframe 5, which the
  // first run also had).
  const size_t reset_at = 120;
  r.spoil_keyframe = [&](size_t i, KeyframeInput& k) {
    k.loops.clear();
    if (i < reset_at) return;
    k.id = i - reset_at;
    if (i < reset_at + 120 || i % 4 != 0) return;
    size_t best = reset_at;
    for (size_t j = reset_at; j + 60 < i; ++j) {
      if (std::hypot(r.truth[j].x - r.truth[i].x, r.truth[j].y - r.truth[i].y) <
          std::hypot(r.truth[best].x - r.truth[i].x, r.truth[best].y - r.truth[i].y)) {
        best = j;
      }
    }
    LoopInput loop;
    loop.candidate = best - reset_at;
    loop.measurement = measure(r.truth[i], r.truth[best], k.id, loop.candidate, true);
    k.loops.push_back(loop);
  };
  r.run();
  ASSERT_NO_FATAL_FAILURE(r.expectSaneResult());
  EXPECT_EQ(r.counters.chains, 2u);
  EXPECT_EQ(r.counters.in_graph, r.truth.size()) << "the back-end keeps adding keyframes after the reset";
  EXPECT_EQ(r.counters.dropped_duplicate, 0u);
  ASSERT_GT(r.loops.size(), 10u);
  for (const LoopEdgeState& loop : r.loops) {
    EXPECT_GE(loop.query, reset_at);
    EXPECT_GE(loop.candidate, reset_at) << "a reused id attached loop " << loop.query << " to the first run";
    EXPECT_TRUE(loop.inlier);
  }
}

TEST(BackendInputs, LoopsStayInsideTheirChain) {
  // Two chains by hand: ids 0..9 (session 0), then a reset: ids 0..9 again. Loops of the second
  // run to its own earlier ids attach to the second chain's nodes.
  GraphBuilder builder(PoseGraphParams{}, BuilderParams{});
  builder.start(Extrinsics::forwardLooking(), 10.0);
  std::vector<ReadyKeyframe> batch;
  for (int run = 0; run < 2; ++run) {
    for (uint64_t id = 0; id < 10; ++id) {
      ReadyKeyframe k;
      k.keyframe.id = id;
      k.keyframe.stamp_ns = kStart + (run * 10 + static_cast<int64_t>(id)) * kPeriod;
      k.odometry = Pose2{0.5 * static_cast<double>(id), run * 3.0, 0.0};
      if (id == 9) {
        LoopInput loop;
        loop.candidate = 2;
        loop.measurement = measure(k.odometry, Pose2{1.0, run * 3.0, 0.0}, 9, 2, true);
        k.keyframe.loops.push_back(loop);
      }
      batch.push_back(k);
    }
  }
  builder.add(batch);
  const std::vector<LoopEdgeState> loops = builder.graph().loops();
  ASSERT_EQ(loops.size(), 2u);
  EXPECT_EQ(loops[0].query, 9u);
  EXPECT_EQ(loops[0].candidate, 2u);
  EXPECT_EQ(loops[1].query, 19u) << "the second run's keyframe 9 is graph node 19";
  EXPECT_EQ(loops[1].candidate, 12u) << "its loop to id 2 is the second run's keyframe 2, not the first's";
  BackendCounters c;
  builder.addCountersTo(c);
  EXPECT_EQ(c.chains, 2u);
  EXPECT_EQ(c.loops_kept, 2u);
}

TEST(BackendInputs, DuplicatesOtherRobotsAndOtherSessionsAreCountedNotMistaken) {
  AdmissionParams params;
  params.robot = "alpha";
  KeyframeAdmission admission(params);
  GraphBuilder builder(PoseGraphParams{}, BuilderParams{});
  builder.start(Extrinsics::forwardLooking(), 10.0);
  for (int i = 0; i <= 20; ++i) {
    admission.addOdometry(kStart + i * kPeriod, Eigen::Vector3d(0.3 * i, 0, 0), Eigen::Quaterniond::Identity());
  }
  const auto keyframe = [](uint64_t id, const std::string& robot) {
    KeyframeInput k;
    k.id = id;
    k.robot = robot;
    k.stamp_ns = kStart + static_cast<int64_t>(id) * kPeriod;
    return k;
  };
  const int64_t now = kStart + 2 * kSecond;
  for (uint64_t id = 0; id < 10; ++id) admission.addKeyframe(keyframe(id, "alpha"), now);
  admission.addKeyframe(keyframe(5, "alpha"), now);   // sent twice
  admission.addKeyframe(keyframe(11, "bravo"), now);  // another robot's keyframe
  KeyframeInput with_loops = keyframe(12, "alpha");
  LoopInput other_robot;
  other_robot.robot = "bravo";
  other_robot.candidate = 3;
  other_robot.measurement = measure(Pose2{3.6, 0, 0}, Pose2{0.9, 0, 0}, 12, 3, true);
  LoopInput other_session = other_robot;
  other_session.robot = "alpha";
  other_session.session = 4;
  LoopInput unknown = other_session;
  unknown.session = 0;
  unknown.candidate = 777;
  with_loops.robot = "alpha";
  with_loops.loops = {other_robot, other_session, unknown};
  admission.addKeyframe(with_loops, now);
  builder.add(admission.takeReady(kStart + 3 * kSecond));
  BackendCounters c;
  admission.addCountersTo(c);
  builder.addCountersTo(c);
  EXPECT_EQ(c.received, 13u);
  EXPECT_EQ(c.in_graph, 11u);
  EXPECT_EQ(c.dropped_duplicate, 1u);
  EXPECT_EQ(c.dropped_other_robot, 1u);
  EXPECT_EQ(c.loops_skipped, 3u);
  EXPECT_EQ(builder.graph().loopCount(), 0u);
  EXPECT_EQ(c.received, c.in_graph + c.waiting + c.dropped());
}

TEST(BackendInputs, AFailedSolveKeepsTheEstimatesAndTheNextOneRecovers) {
  PoseGraphParams params;
  params.max_coordinate = 40.0;  // a solve that moves a keyframe beyond it has failed
  params.robust_loss = "none";   // so that one loop can pull that far
  GraphBuilder builder(params, BuilderParams{});
  builder.start(Extrinsics::forwardLooking(), 10.0);
  const auto keyframe = [](uint64_t id) {
    ReadyKeyframe k;
    k.keyframe.id = id;
    k.keyframe.stamp_ns = kStart + static_cast<int64_t>(id) * kPeriod;
    k.odometry = Pose2{1.9 * static_cast<double>(id), 0.0, 0.0};
    return k;
  };
  std::vector<ReadyKeyframe> batch;
  for (uint64_t id = 0; id < 10; ++id) batch.push_back(keyframe(id));
  builder.add(batch);
  const std::vector<Pose2> before = builder.graph().estimates();
  // A loop (valid: 100 m is within max_loop_distance) that says keyframe 10 is 100 m from keyframe 0.
  ReadyKeyframe pull = keyframe(10);
  LoopInput loop;
  loop.candidate = 0;
  loop.measurement = measure(Pose2{0, 0, 0}, Pose2{-100.0, 0, 0}, 10, 0, true);
  pull.keyframe.loops.push_back(loop);
  const BatchResult failed = builder.add({pull});
  EXPECT_TRUE(failed.solved);
  EXPECT_TRUE(failed.stats.failed);
  BackendCounters c;
  builder.addCountersTo(c);
  EXPECT_EQ(c.solves_failed, 1u);
  EXPECT_EQ(c.loops_refused, 1u) << "the loop that broke the solve is taken out";
  EXPECT_EQ(builder.graph().loopCount(), 0u);
  for (size_t i = 0; i < before.size(); ++i) EXPECT_DOUBLE_EQ(builder.graph().estimate(i).x, before[i].x);
  // The next loop solves.
  ReadyKeyframe next = keyframe(11);
  loop.candidate = 5;
  loop.measurement = measure(Pose2{1.9 * 11, 0, 0}, Pose2{1.9 * 5, 0, 0}, 11, 5, true);
  next.keyframe.loops = {loop};
  const BatchResult recovered = builder.add({next});
  EXPECT_TRUE(recovered.solved);
  EXPECT_FALSE(recovered.stats.failed);
  c = {};
  builder.addCountersTo(c);
  EXPECT_EQ(c.solves, 2u);
  EXPECT_EQ(c.solves_failed, 1u);
  EXPECT_EQ(c.loops_kept, 1u);
}

}  // namespace
}  // namespace mild::backend
