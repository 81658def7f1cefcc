#pragma once

// What the example back-end received, kept and lost, by cause: published as its diagnostics, so
// that every keyframe is accounted for (received = in graph + waiting + dropped) and every refused
// value is counted, never only logged.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace mild::backend {

struct BackendCounters {
  // Keyframes (one LoopClosure message each).
  uint64_t received = 0;
  uint64_t in_graph = 0;
  uint64_t waiting = 0;
  uint64_t dropped_no_odometry = 0;    // no odometry (or tf) at its stamp within odometry_wait
  uint64_t dropped_future_stamp = 0;   // stamped more than max_future_stamp ahead of the clock
  uint64_t dropped_duplicate = 0;      // the same id and stamp as a keyframe already in the graph
  uint64_t dropped_odometry_jump = 0;  // its odometry moved more than max_odometry_step from the last keyframe's
  uint64_t dropped_invalid_pose = 0;   // its pose (interpolated odometry or tf) non-finite or out of range
  uint64_t dropped_other_robot = 0;    // query_robot is not the robot this back-end follows
  uint64_t dropped_queue_full = 0;     // more than max_waiting keyframes waited for their pose
  // Inputs refused at the boundary.
  uint64_t odometry_rejected = 0;  // odometry messages: non-finite, out of range, or not a rotation
  uint64_t tf_rejected = 0;        // camera mountings (tf base -> camera) refused
  // Loops.
  uint64_t loops_kept = 0;      // in the graph and inliers after the last solve
  uint64_t loops_rejected = 0;  // in the graph, outliers after the last solve (the robust loss holds them)
  uint64_t loops_refused = 0;   // measurement non-finite or absurd, or a keyframe's copy or excess: never added
  uint64_t loops_skipped = 0;   // another robot's or another session's keyframe, or one not in the graph
  // Solves.
  uint64_t solves = 0;
  uint64_t solves_failed = 0;  // the estimates from before the solve were kept
  uint64_t chains = 0;         // odometry chains: one per detector session or reset, or odometry restart

  uint64_t dropped() const {
    return dropped_no_odometry + dropped_future_stamp + dropped_duplicate + dropped_odometry_jump +
           dropped_invalid_pose + dropped_other_robot + dropped_queue_full;
  }
  // Every counter by its diagnostics name, in a fixed order.
  std::vector<std::pair<std::string, uint64_t>> named() const;
};

}  // namespace mild::backend
