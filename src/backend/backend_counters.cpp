#include "mild_lcd/backend/backend_counters.hpp"

namespace mild::backend {

std::vector<std::pair<std::string, uint64_t>> BackendCounters::named() const {
  return {{"keyframes received", received},
          {"keyframes in graph", in_graph},
          {"keyframes waiting", waiting},
          {"keyframes dropped", dropped()},
          {"dropped: no odometry", dropped_no_odometry},
          {"dropped: future stamp", dropped_future_stamp},
          {"dropped: duplicate", dropped_duplicate},
          {"dropped: odometry jump", dropped_odometry_jump},
          {"dropped: invalid pose", dropped_invalid_pose},
          {"dropped: other robot", dropped_other_robot},
          {"dropped: queue full", dropped_queue_full},
          {"odometry rejected", odometry_rejected},
          {"tf rejected", tf_rejected},
          {"loops kept", loops_kept},
          {"loops rejected", loops_rejected},
          {"loops refused", loops_refused},
          {"loops skipped", loops_skipped},
          {"solves", solves},
          {"solves failed", solves_failed},
          {"chains", chains}};
}

}  // namespace mild::backend
