#pragma once

// Turns the keyframes that left the waiting room (backend/keyframe_admission.hpp) into the pose
// graph: which chain each keyframe continues, which of its loops the graph may take, one solve per
// batch. Owned by the back-end's update thread; ROS-free.
//
// Chains follow the detector's ids. Ids are unique within a session of one detector run; the
// detector's `reset` starts again at id 0 in session 0, and a load or merge starts a new session.
// So a keyframe starts a new chain of ids when its session differs from the chain's, or its id is
// not above the chain's last (a reset); the odometry edge to the previous keyframe stays (the
// robot's motion is measured all the same). The same id with the same stamp as a keyframe of the chain is a
// duplicate message and is dropped. A loop is taken only between keyframes of the same robot and
// session whose candidate is in the current chain: a reused id never links two sessions.
//
// Odometry jumps: a keyframe whose odometry moved more than max_odometry_step from the previous
// keyframe's is dropped (one spike); after jumps_for_new_chain such keyframes in a row the
// odometry itself restarted, and that one starts a new odometry chain: no odometry edge, held near
// the previous keyframe's estimate (PoseGraph2D::addKeyframe's new_chain).

#include <cstdint>
#include <memory>
#include <optional>
#include <unordered_map>
#include <vector>

#include "mild_lcd/backend/backend_counters.hpp"
#include "mild_lcd/backend/keyframe_admission.hpp"
#include "mild_lcd/backend/pose_graph.hpp"

namespace mild::backend {

struct BuilderParams {
  double max_odometry_step = 50.0;  // metres between consecutive keyframes' odometry
  int jumps_for_new_chain = 3;
};

struct BatchResult {
  size_t added = 0;        // keyframes added to the graph
  bool solved = false;     // a loop was added: the graph was solved
  UpdateStats stats;       // of that solve
  double update_ms = 0.0;  // the whole batch: adding and solving
};

class GraphBuilder {
 public:
  GraphBuilder(const PoseGraphParams& graph_params, const BuilderParams& params);

  // Creates the graph with the camera's mounting. Returns false (counted in tf_rejected, and a
  // forward-looking camera at the base's origin used instead) when the extrinsics are not a
  // rotation and a finite translation within max_extrinsics_distance metres.
  bool start(const Extrinsics& extrinsics, double max_extrinsics_distance);
  bool started() const { return graph_ != nullptr; }

  // Adds the keyframes in order, their loops, and solves once if any loop was added. Never throws
  // for bad input: whatever cannot be added is counted.
  BatchResult add(std::vector<ReadyKeyframe> batch);

  const PoseGraph2D& graph() const { return *graph_; }
  // The stamp of each keyframe of the graph, in graph order.
  const std::vector<int64_t>& stamps() const { return stamps_; }
  // The counters this stage owns (in graph, duplicate, odometry jump, invalid pose, loops, solves,
  // chains, tf_rejected).
  void addCountersTo(BackendCounters& counters) const;

 private:
  enum class Continuation { kSameChain, kNewChain, kDuplicate };
  Continuation classify(const KeyframeInput& keyframe) const;
  bool addLoops(const ReadyKeyframe& ready, uint64_t node);

  PoseGraphParams graph_params_;
  BuilderParams params_;
  std::unique_ptr<PoseGraph2D> graph_;
  std::vector<int64_t> stamps_;
  // The current chain: its session, last id, and each of its ids' graph node.
  uint32_t chain_session_ = 0;
  uint64_t chain_last_id_ = 0;
  std::unordered_map<uint64_t, uint64_t> chain_nodes_;
  int jumps_in_a_row_ = 0;
  BackendCounters counters_;
};

}  // namespace mild::backend
