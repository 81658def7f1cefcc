#pragma once

// The example back-end's waiting room: keyframes (LoopClosure messages) arrive before or after the
// odometry at their stamp; each waits here until its odometry pose is known, bounded in time (in
// both directions of the clock) and in count, and leaves either with its pose or counted as dropped
// with its cause. Odometry is validated here, at the boundary. ROS-free and single-threaded (the
// nodelet holds one mutex around it); stamps are integer nanoseconds, as ros::Time carries them, so
// that a tf lookup happens at the keyframe's exact stamp.

#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "mild_lcd/backend/backend_counters.hpp"
#include "mild_lcd/backend/pose2.hpp"
#include "mild_lcd/backend/pose_graph.hpp"

namespace mild::backend {

struct AdmissionParams {
  double odometry_wait = 2.0;     // seconds a keyframe waits for its pose
  double max_future_stamp = 1.0;  // seconds a keyframe's stamp may be ahead of the clock
  size_t max_waiting = 1000;      // keyframes waiting at most; the oldest is dropped beyond
  size_t max_odometry = 100000;   // odometry samples kept (oldest forgotten)
  double max_coordinate = 1e5;    // metres; farther odometry is refused
  std::string robot;              // the robot whose keyframes form the trajectory; empty: the first seen
};

// A loop from one of the keyframe's candidates (only those the nodelet chose to use).
struct LoopInput {
  uint64_t candidate = 0;
  uint32_t session = 0;
  std::string robot;
  LoopMeasurement measurement;  // query and candidate ids filled as the detector numbered them
};

struct KeyframeInput {
  int64_t stamp_ns = 0;
  uint64_t id = 0;
  uint32_t session = 0;
  std::string robot;
  std::string camera_frame;
  std::vector<LoopInput> loops;
};

struct ReadyKeyframe {
  KeyframeInput keyframe;
  Pose2 odometry;
};

// A 3-D pose read as a planar one (x, y, yaw about z), or nullopt when it is not finite, farther
// than max_coordinate, or its quaternion is not (nearly) a unit one.
std::optional<Pose2> planarPose(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation,
                                double max_coordinate);

class KeyframeAdmission {
 public:
  // The pose at a stamp when keyframe poses come from tf: nullopt while it is not known yet.
  using PoseAt = std::function<std::optional<Pose2>(int64_t stamp_ns)>;

  explicit KeyframeAdmission(const AdmissionParams& params);

  // Odometry at a stamp. Returns false (counted in odometry_rejected) for a non-finite or
  // out-of-range pose. An older stamp than the newest means the source restarted (a bag played
  // again): the buffer starts over.
  bool addOdometry(int64_t stamp_ns, const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation);

  // A keyframe arriving at now_ns (the clock; 0 when it has not started: no future check). Dropped
  // at once, counted, when it is another robot's or stamped beyond max_future_stamp; the oldest
  // waiting keyframe is dropped when max_waiting are waiting. Of its loops, a second one to the same
  // candidate keyframe and any beyond kMaxLoopsPerKeyframe are refused (counted in loops_refused).
  void addKeyframe(KeyframeInput keyframe, int64_t now_ns);
  // Far more than the detector reports for one keyframe (detector/max_candidates and
  // detector/similarity_candidates, each at most 100).
  static constexpr size_t kMaxLoopsPerKeyframe = 256;

  // Every keyframe, oldest first, whose pose is known: with the odometry topic, interpolated
  // between the samples around its stamp; with pose_at (tf), from it. Stops at the first that must
  // still wait (keyframes enter the graph in order); drops, counted, those that waited longer than
  // odometry_wait or whose stamp is older than the oldest odometry kept.
  std::vector<ReadyKeyframe> takeReady(int64_t now_ns, const PoseAt& pose_at = nullptr);

  // The counters this stage owns: received, waiting, dropped (no odometry, future stamp, invalid
  // pose, other robot, queue full), odometry_rejected and the loops it refused.
  void addCountersTo(BackendCounters& counters) const;
  const std::string& robot() const { return robot_; }

 private:
  struct Waiting {
    KeyframeInput keyframe;
    int64_t arrival_ns = 0;
  };
  std::optional<Pose2> odometryAt(int64_t stamp_ns, bool& give_up) const;
  void boundLoops(KeyframeInput& keyframe);

  AdmissionParams params_;
  std::string robot_;
  bool robot_known_ = false;
  std::deque<std::pair<int64_t, Pose2>> odometry_;
  std::deque<Waiting> waiting_;
  BackendCounters counters_;
};

}  // namespace mild::backend
