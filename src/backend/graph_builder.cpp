#include "mild_lcd/backend/graph_builder.hpp"

#include <chrono>
#include <cmath>

namespace mild::backend {

GraphBuilder::GraphBuilder(const PoseGraphParams& graph_params, const BuilderParams& params)
    : graph_params_(graph_params), params_(params) {}

bool GraphBuilder::start(const Extrinsics& extrinsics, double max_extrinsics_distance) {
  const bool valid = extrinsicsAreValid(extrinsics, max_extrinsics_distance);
  if (!valid) ++counters_.tf_rejected;
  graph_ = std::make_unique<PoseGraph2D>(graph_params_, valid ? extrinsics : Extrinsics::forwardLooking());
  return valid;
}

GraphBuilder::Continuation GraphBuilder::classify(const KeyframeInput& keyframe) const {
  if (graph_->size() == 0 || keyframe.session != chain_session_) return Continuation::kNewChain;
  const auto known = chain_nodes_.find(keyframe.id);
  if (known != chain_nodes_.end() && stamps_[known->second] == keyframe.stamp_ns) return Continuation::kDuplicate;
  // Ids only grow within a session; one that does not was numbered after a reset.
  if (known != chain_nodes_.end() || keyframe.id <= chain_last_id_) return Continuation::kNewChain;
  return Continuation::kSameChain;
}

BatchResult GraphBuilder::add(std::vector<ReadyKeyframe> batch) {
  const auto start = std::chrono::steady_clock::now();
  BatchResult result;
  bool loops_added = false;
  const size_t loops_before = graph_->loopCount();
  for (ReadyKeyframe& ready : batch) {
    const KeyframeInput& k = ready.keyframe;
    if (!graph_->acceptablePose(ready.odometry)) {
      ++counters_.dropped_invalid_pose;
      continue;
    }
    const Continuation continuation = classify(k);
    if (continuation == Continuation::kDuplicate) {
      ++counters_.dropped_duplicate;
      continue;
    }
    // A new id chain (reset, session) keeps the odometry edge: the robot's motion is still measured.
    bool new_odometry_chain = graph_->size() == 0;
    if (!new_odometry_chain) {
      const Pose2 step = between(graph_->odometry(graph_->size() - 1), ready.odometry);
      if (std::hypot(step.x, step.y) > params_.max_odometry_step) {
        if (++jumps_in_a_row_ < params_.jumps_for_new_chain) {
          ++counters_.dropped_odometry_jump;
          continue;
        }
        new_odometry_chain = true;  // not a spike: the odometry restarted
      }
    }
    jumps_in_a_row_ = 0;
    if (continuation == Continuation::kNewChain) {
      chain_nodes_.clear();
      chain_session_ = k.session;
    }
    if (continuation == Continuation::kNewChain || new_odometry_chain) ++counters_.chains;
    const uint64_t node = graph_->size();
    graph_->addKeyframe(node, ready.odometry, new_odometry_chain && node > 0);
    stamps_.push_back(k.stamp_ns);
    chain_nodes_[k.id] = node;
    chain_last_id_ = k.id;
    ++result.added;
    loops_added |= addLoops(ready, node);
  }
  if (loops_added) {
    result.stats = graph_->optimize();
    result.solved = true;
    ++counters_.solves;
    if (result.stats.failed) {
      // The estimates are back to before the solve; the loops that made it fail go, so that the
      // next solve starts from a graph that solved.
      ++counters_.solves_failed;
      counters_.loops_refused += graph_->loopCount() - loops_before;
      graph_->truncateLoops(loops_before);
    }
    counters_.loops_kept = counters_.loops_rejected = 0;
    for (const LoopEdgeState& loop : graph_->loops()) ++(loop.inlier ? counters_.loops_kept : counters_.loops_rejected);
  }
  counters_.in_graph = graph_->size();
  result.update_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return result;
}

bool GraphBuilder::addLoops(const ReadyKeyframe& ready, uint64_t node) {
  bool added = false;
  for (const LoopInput& loop : ready.keyframe.loops) {
    const auto candidate = chain_nodes_.find(loop.candidate);
    if (loop.robot != ready.keyframe.robot || loop.session != ready.keyframe.session ||
        candidate == chain_nodes_.end() || candidate->second == node) {
      ++counters_.loops_skipped;
      continue;
    }
    LoopMeasurement m = loop.measurement;
    m.query = node;
    m.candidate = candidate->second;
    if (!measurementIsValid(m, graph_params_.max_loop_distance) || !graph_->addLoop(m)) {
      ++counters_.loops_refused;
      continue;
    }
    added = true;
  }
  return added;
}

void GraphBuilder::addCountersTo(BackendCounters& c) const {
  c.in_graph += counters_.in_graph;
  c.dropped_duplicate += counters_.dropped_duplicate;
  c.dropped_odometry_jump += counters_.dropped_odometry_jump;
  c.dropped_invalid_pose += counters_.dropped_invalid_pose;
  c.tf_rejected += counters_.tf_rejected;
  c.loops_kept += counters_.loops_kept;
  c.loops_rejected += counters_.loops_rejected;
  c.loops_refused += counters_.loops_refused;
  c.loops_skipped += counters_.loops_skipped;
  c.solves += counters_.solves;
  c.solves_failed += counters_.solves_failed;
  c.chains += counters_.chains;
}

}  // namespace mild::backend
