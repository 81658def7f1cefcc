#include "mild_lcd/backend/keyframe_admission.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <tuple>

namespace mild::backend {
namespace {

int64_t nanoseconds(double seconds) { return static_cast<int64_t>(seconds * 1e9); }

}  // namespace

std::optional<Pose2> planarPose(const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation,
                                double max_coordinate) {
  const Eigen::Vector4d q = orientation.coeffs();
  if (!position.allFinite() || !q.allFinite()) return std::nullopt;
  if (position.norm() > max_coordinate || std::abs(q.norm() - 1.0) > 0.1) return std::nullopt;
  const Eigen::Quaterniond u = orientation.normalized();
  const double yaw = std::atan2(2.0 * (u.w() * u.z() + u.x() * u.y()), 1.0 - 2.0 * (u.y() * u.y() + u.z() * u.z()));
  return Pose2{position.x(), position.y(), yaw};
}

KeyframeAdmission::KeyframeAdmission(const AdmissionParams& params)
    : params_(params), robot_(params.robot), robot_known_(!params.robot.empty()) {}

bool KeyframeAdmission::addOdometry(int64_t stamp_ns, const Eigen::Vector3d& position,
                                    const Eigen::Quaterniond& orientation) {
  const std::optional<Pose2> pose = planarPose(position, orientation, params_.max_coordinate);
  if (!pose) {
    ++counters_.odometry_rejected;
    return false;
  }
  if (!odometry_.empty() && stamp_ns <= odometry_.back().first) {
    if (stamp_ns == odometry_.back().first) return true;  // the same sample again
    odometry_.clear();                                    // time went back: the source restarted
  }
  odometry_.emplace_back(stamp_ns, *pose);
  while (odometry_.size() > params_.max_odometry) odometry_.pop_front();
  return true;
}

void KeyframeAdmission::boundLoops(KeyframeInput& keyframe) {
  // One loop per candidate keyframe, the first given, and at most kMaxLoopsPerKeyframe: the waiting
  // room bounds keyframes, this bounds what each may bring (every loop is a residual of each solve).
  std::set<std::tuple<std::string, uint32_t, uint64_t>> seen;
  std::vector<LoopInput> kept;
  for (LoopInput& loop : keyframe.loops) {
    if (kept.size() >= kMaxLoopsPerKeyframe || !seen.emplace(loop.robot, loop.session, loop.candidate).second) {
      ++counters_.loops_refused;
      continue;
    }
    kept.push_back(std::move(loop));
  }
  keyframe.loops = std::move(kept);
}

void KeyframeAdmission::addKeyframe(KeyframeInput keyframe, int64_t now_ns) {
  ++counters_.received;
  if (!robot_known_) {
    robot_ = keyframe.robot;
    robot_known_ = true;
  }
  if (keyframe.robot != robot_) {
    ++counters_.dropped_other_robot;
    return;
  }
  // A stamp far ahead would wait at the head of the queue, and everything after it behind it.
  if (now_ns > 0 && keyframe.stamp_ns - now_ns > nanoseconds(params_.max_future_stamp)) {
    ++counters_.dropped_future_stamp;
    return;
  }
  boundLoops(keyframe);
  if (waiting_.size() >= params_.max_waiting) {
    waiting_.pop_front();
    ++counters_.dropped_queue_full;
  }
  waiting_.push_back(Waiting{std::move(keyframe), now_ns});
}

std::optional<Pose2> KeyframeAdmission::odometryAt(int64_t stamp_ns, bool& give_up) const {
  give_up = false;
  if (odometry_.empty() || stamp_ns > odometry_.back().first) return std::nullopt;  // not yet
  if (stamp_ns < odometry_.front().first) {
    give_up = true;  // older than anything kept: it will never come
    return std::nullopt;
  }
  const auto after = std::lower_bound(odometry_.begin(), odometry_.end(), stamp_ns,
                                      [](const auto& o, int64_t t) { return o.first < t; });
  if (after->first == stamp_ns || after == odometry_.begin()) return after->second;
  const auto before = std::prev(after);
  const double f = static_cast<double>(stamp_ns - before->first) / static_cast<double>(after->first - before->first);
  const Pose2 step = between(before->second, after->second);
  return compose(before->second, Pose2{f * step.x, f * step.y, f * step.yaw});
}

std::vector<ReadyKeyframe> KeyframeAdmission::takeReady(int64_t now_ns, const PoseAt& pose_at) {
  std::vector<ReadyKeyframe> ready;
  while (!waiting_.empty()) {
    Waiting& head = waiting_.front();
    // The clock went back (a bag played again, simulated time restarted): the wait starts over.
    if (now_ns < head.arrival_ns) head.arrival_ns = now_ns;
    bool give_up = false;
    std::optional<Pose2> pose;
    if (pose_at) {
      pose = pose_at(head.keyframe.stamp_ns);
    } else {
      pose = odometryAt(head.keyframe.stamp_ns, give_up);
    }
    if (pose) {
      // Odometry samples were checked on arrival; a pose from tf is checked here.
      if (!std::isfinite(pose->x) || !std::isfinite(pose->y) || !std::isfinite(pose->yaw) ||
          std::hypot(pose->x, pose->y) > params_.max_coordinate) {
        ++counters_.dropped_invalid_pose;
        if (pose_at) ++counters_.tf_rejected;
      } else {
        ready.push_back(ReadyKeyframe{std::move(head.keyframe), *pose});
      }
      waiting_.pop_front();
      continue;
    }
    give_up = give_up || now_ns - head.arrival_ns > nanoseconds(params_.odometry_wait);
    if (!give_up) break;
    ++counters_.dropped_no_odometry;
    waiting_.pop_front();
  }
  return ready;
}

void KeyframeAdmission::addCountersTo(BackendCounters& c) const {
  c.received += counters_.received;
  c.waiting += waiting_.size();
  c.dropped_no_odometry += counters_.dropped_no_odometry;
  c.dropped_future_stamp += counters_.dropped_future_stamp;
  c.dropped_invalid_pose += counters_.dropped_invalid_pose;
  c.dropped_other_robot += counters_.dropped_other_robot;
  c.dropped_queue_full += counters_.dropped_queue_full;
  c.odometry_rejected += counters_.odometry_rejected;
  c.tf_rejected += counters_.tf_rejected;
  c.loops_refused += counters_.loops_refused;
}

}  // namespace mild::backend
