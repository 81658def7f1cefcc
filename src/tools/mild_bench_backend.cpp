// mild_bench_backend: the example back-end (mild_lcd/PoseGraphNodelet) under a long, fast run, fed by
// this node instead of the detector. It must keep up or say what it dropped: a back-end that falls
// behind loses keyframes in its subscription queue, where nobody counts them.
// For each keyframe, one nav_msgs/Odometry on `odom` (the keyframe's stamp), then, a few milliseconds
// later as a detector's answer comes after the odometry, one mild_lcd/LoopClosure on `loop_closure`
// with the same stamp. The robot drives laps of a 40 m x 20 m rectangle at 1 m per keyframe, each lap
// inset a little from the first (0 to 1.5 m), so that later laps pass within 1 m of earlier ones at
// varying distances; its odometry drifts (backend/trajectory.hpp's default model). When a keyframe is
// within 1 m of a keyframe of an earlier lap, the LoopClosure holds one accepted, verified candidate
// (the nearest) with its true metric relative pose, for a forward-looking camera at the base's origin.
// Paced by the wall clock (no simulated time). Every --sample-every keyframes, and once at the end
// (after "keyframes waiting" reaches 0, or --settle seconds), it prints the back-end's newest
// diagnostics (the status whose name ends with "pose graph") as a Markdown table row, then a summary.
// Exits 0 when the back-end received every keyframe sent and accounts for each (received = in graph +
// waiting + dropped), 1 otherwise, 2 for bad options.
//   mild_bench_backend --keyframes 12000 --rate 40        # or _keyframes:=12000 _rate:=40

#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include <CLI/CLI.hpp>

#include <diagnostic_msgs/DiagnosticArray.h>
#include <nav_msgs/Odometry.h>
#include <ros/ros.h>
#include <Eigen/Geometry>
#include "common/ros_quaternion.hpp"
#include "common/tool_main.hpp"

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/backend/pose2.hpp"
#include "mild_lcd/backend/trajectory.hpp"
#include "mild_lcd/common/errors.hpp"

namespace {

using mild::backend::Pose2;

struct Options {
  int keyframes = 12000;
  double rate = 40.0;
  int sample_every = 1000;
  double settle = 60.0;
  int seed = 1;
};

constexpr double kLength = 40.0, kWidth = 20.0;  // the rectangle, metres
constexpr double kStep = 1.0;                    // metres between keyframes
constexpr double kLoopRadius = 1.0;              // a loop when an earlier lap's keyframe is this close
constexpr double kMaxInset = 1.5;                // laps run up to this far inside the first one

// ---------------------------------------------------------------------------------------------
// The synthetic run.

// Lap `lap`'s inset: 0 for the first, then spread over [0, kMaxInset) by the golden ratio, so that
// every lap passes at another distance from the earlier ones.
double insetOf(int lap) {
  if (lap == 0) return 0.0;
  const double f = lap * 0.6180339887498949;
  return kMaxInset * (f - std::floor(f));
}

double perimeterOf(double inset) { return 2.0 * (kLength - 2.0 * inset) + 2.0 * (kWidth - 2.0 * inset); }

// The pose at arc length s along the rectangle inset by `inset`, counterclockwise from its corner
// nearest the origin, heading along the side.
Pose2 onRectangle(double s, double inset) {
  const double a = kLength - 2.0 * inset, b = kWidth - 2.0 * inset;
  const double x0 = inset, y0 = inset, half_pi = mild::backend::kPi / 2;
  if (s < a) return {x0 + s, y0, 0.0};
  s -= a;
  if (s < b) return {x0 + a, y0 + s, half_pi};
  s -= b;
  if (s < a) return {x0 + a - s, y0 + b, mild::backend::kPi};
  s -= a;
  return {x0, y0 + b - std::min(s, b), -half_pi};
}

struct Run {
  std::vector<Pose2> truth;
  std::vector<Pose2> odometry;
  std::vector<int> lap;
  std::vector<long> candidate;  // the loop's earlier keyframe, -1 for none
  size_t loops = 0;
};

// Earlier keyframes by 1 m cell, for the nearest one within kLoopRadius of an earlier lap.
class Grid {
 public:
  void add(size_t k, const Pose2& p) { cells_[key(cellOf(p.x), cellOf(p.y))].push_back(k); }

  long nearestOfEarlierLap(const Pose2& p, int lap, const std::vector<Pose2>& truth,
                           const std::vector<int>& laps) const {
    long best = -1;
    double best_d = kLoopRadius;
    for (long cx = cellOf(p.x) - 1; cx <= cellOf(p.x) + 1; ++cx) {
      for (long cy = cellOf(p.y) - 1; cy <= cellOf(p.y) + 1; ++cy) {
        const auto it = cells_.find(key(cx, cy));
        if (it == cells_.end()) continue;
        for (size_t k : it->second) {
          if (laps[k] >= lap) continue;
          const double d = std::hypot(truth[k].x - p.x, truth[k].y - p.y);
          if (d <= best_d) {  // ties: the most recent (added last), as a detector prefers
            best_d = d;
            best = static_cast<long>(k);
          }
        }
      }
    }
    return best;
  }

 private:
  static long cellOf(double v) { return static_cast<long>(std::floor(v / kLoopRadius)); }
  static int64_t key(long cx, long cy) { return (static_cast<int64_t>(cx) << 32) ^ (cy & 0xffffffffL); }
  std::unordered_map<int64_t, std::vector<size_t>> cells_;
};

Run makeRun(const Options& opt) {
  Run run;
  int lap = 0;
  double s = 0.0;
  for (int k = 0; k < opt.keyframes; ++k) {
    while (s >= perimeterOf(insetOf(lap))) s -= perimeterOf(insetOf(lap++));
    run.truth.push_back(onRectangle(s, insetOf(lap)));
    run.lap.push_back(lap);
    s += kStep;
  }
  mild::backend::DriftModel drift;
  drift.seed = static_cast<uint64_t>(opt.seed);
  run.odometry = mild::backend::driftedOdometry(run.truth, drift);
  Grid grid;
  for (size_t k = 0; k < run.truth.size(); ++k) {
    run.candidate.push_back(grid.nearestOfEarlierLap(run.truth[k], run.lap[k], run.truth, run.lap));
    if (run.candidate.back() >= 0) ++run.loops;
    grid.add(k, run.truth[k]);
  }
  return run;
}

// The candidate camera's true pose in the query camera's optical frame (LoopCandidate's convention),
// for a camera at the base's origin looking along its x axis: optical z = base x, x = -base y,
// y = -base z (the back-end's fallback mounting when tf has none).
void setRelativePose(const Pose2& query, const Pose2& candidate, mild_lcd::LoopCandidate& c) {
  Eigen::Matrix3d base_from_camera;
  base_from_camera.col(0) = Eigen::Vector3d(0, -1, 0);
  base_from_camera.col(1) = Eigen::Vector3d(0, 0, -1);
  base_from_camera.col(2) = Eigen::Vector3d(1, 0, 0);
  const Pose2 rel = mild::backend::between(query, candidate);  // candidate base in the query base
  const Eigen::Matrix3d rotation =
      base_from_camera.transpose() * Eigen::AngleAxisd(rel.yaw, Eigen::Vector3d::UnitZ()) * base_from_camera;
  const Eigen::Vector3d translation = base_from_camera.transpose() * Eigen::Vector3d(rel.x, rel.y, 0.0);
  c.has_relative_pose = true;
  c.metric_translation = true;
  c.relative_rotation = mild::tools::quaternion(Eigen::Quaterniond(rotation).normalized());
  c.relative_translation.x = translation.x();
  c.relative_translation.y = translation.y();
  c.relative_translation.z = translation.z();
}

// ---------------------------------------------------------------------------------------------
// The back-end's diagnostics.

using Status = std::map<std::string, std::string>;

// The newest status of /diagnostics whose name ends with "pose graph", and when it arrived.
class BackendStatus {
 public:
  BackendStatus() { sub_ = ros::NodeHandle().subscribe("/diagnostics", 100, &BackendStatus::onDiagnostics, this); }

  std::optional<Status> latest(ros::WallTime* arrived = nullptr) const {
    std::lock_guard<std::mutex> lock(mutex_);
    if (arrived) *arrived = arrived_;
    return latest_;
  }

  bool waitForFirst(double timeout_s) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] { return latest_.has_value(); });
  }

 private:
  void onDiagnostics(const diagnostic_msgs::DiagnosticArray::ConstPtr& msg) {
    const std::string suffix = "pose graph";
    for (const auto& s : msg->status) {
      if (s.name.size() < suffix.size() || s.name.compare(s.name.size() - suffix.size(), suffix.size(), suffix) != 0)
        continue;
      Status values;
      for (const auto& kv : s.values) values[kv.key] = kv.value;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        latest_ = std::move(values);
        arrived_ = ros::WallTime::now();
      }
      cv_.notify_all();
    }
  }

  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::optional<Status> latest_;
  ros::WallTime arrived_;
};

// An integer entry; -1 when missing or not a number (so that the final checks fail on it).
long long count(const Status& s, const std::string& key) {
  const auto it = s.find(key);
  if (it == s.end()) return -1;
  try {
    return std::stoll(it->second);
  } catch (const std::exception&) {
    return -1;
  }
}

std::string text(const Status& s, const std::string& key) {
  const auto it = s.find(key);
  return it == s.end() ? "?" : it->second;
}

// The nonzero "dropped: <cause>" entries, e.g. "queue full 12, no odometry 3"; "-" when none.
std::string dropCauses(const Status& s) {
  const std::string prefix = "dropped: ";
  std::string out;
  for (const auto& [key, value] : s) {
    if (key.compare(0, prefix.size(), prefix) != 0 || count(s, key) == 0) continue;
    out += (out.empty() ? "" : ", ") + key.substr(prefix.size()) + " " + value;
  }
  return out.empty() ? "-" : out;
}

void printHeader() {
  std::printf(
      "| keyframes sent | received | in graph | waiting | dropped | dropped by cause | update ms median | update ms "
      "p95 | update keyframes | loops kept |\n|---|---|---|---|---|---|---|---|---|---|\n");
}

void printRow(long sent, const Status& s) {
  std::printf("| %ld | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", sent, text(s, "keyframes received").c_str(),
              text(s, "keyframes in graph").c_str(), text(s, "keyframes waiting").c_str(),
              text(s, "keyframes dropped").c_str(), dropCauses(s).c_str(), text(s, "update ms median").c_str(),
              text(s, "update ms p95").c_str(), text(s, "update keyframes").c_str(), text(s, "loops kept").c_str());
  std::fflush(stdout);
}

// ---------------------------------------------------------------------------------------------
// The benchmark.

// Waits for a back-end on both topics and for its first diagnostics.
void waitForBackend(const ros::Publisher& odom_pub, const ros::Publisher& loop_pub, BackendStatus& status) {
  const ros::WallTime connect_end = ros::WallTime::now() + ros::WallDuration(60.0);
  while (ros::ok() && ros::WallTime::now() < connect_end &&
         (odom_pub.getNumSubscribers() == 0 || loop_pub.getNumSubscribers() == 0)) {
    ros::WallDuration(0.05).sleep();
  }
  if (odom_pub.getNumSubscribers() == 0 || loop_pub.getNumSubscribers() == 0) {
    throw std::runtime_error("no back-end subscribes to " + odom_pub.getTopic() + " and " + loop_pub.getTopic() +
                             " (60 s)");
  }
  if (!status.waitForFirst(30.0)) {
    throw std::runtime_error("no diagnostics status whose name ends with \"pose graph\" on /diagnostics (30 s)");
  }
}

void printIntro(const Options& opt, const Run& run) {
  std::printf(
      "example back-end under load: %d keyframes at %.0f Hz (wall clock), laps of a %.0f m x %.0f m rectangle "
      "at %.0f m per keyframe (%d laps), drifting odometry, %zu loops (nearest keyframe of an earlier lap "
      "within %.0f m)\n\n",
      opt.keyframes, opt.rate, kLength, kWidth, kStep, run.lap.back() + 1, run.loops, kLoopRadius);
  printHeader();
}

nav_msgs::Odometry odometryMsg(const ros::Time& stamp, const Pose2& pose) {
  nav_msgs::Odometry odom;
  odom.header.stamp = stamp;
  odom.header.frame_id = "odom";
  odom.child_frame_id = "base_link";
  odom.pose.pose.position.x = pose.x;
  odom.pose.pose.position.y = pose.y;
  odom.pose.pose.orientation =
      mild::tools::quaternion(Eigen::Quaterniond(Eigen::AngleAxisd(pose.yaw, Eigen::Vector3d::UnitZ())));
  return odom;
}

// Keyframe k's LoopClosure: its loop's candidate, if it has one, accepted and verified with its true pose.
mild_lcd::LoopClosure loopClosureMsg(const Run& run, size_t k, const ros::Time& stamp,
                                     const std::vector<ros::Time>& stamps) {
  mild_lcd::LoopClosure closure;
  closure.header.stamp = stamp;
  closure.header.frame_id = "camera";
  closure.query_id = k;
  closure.query_session = 0;
  closure.database_size = static_cast<int32_t>(k + 1);
  if (run.candidate[k] >= 0) {
    const size_t j = static_cast<size_t>(run.candidate[k]);
    mild_lcd::LoopCandidate c;
    c.id = j;
    c.session = 0;
    c.stamp = stamps[j];
    c.probability = c.filter_probability = 0.99;
    c.accepted = c.verified = true;
    c.inliers = c.matches = c.pose_inliers = 100;
    c.inlier_ratio = 1.0;
    c.reprojection_error = 1.0;
    setRelativePose(run.truth[k], run.truth[j], c);
    closure.candidates.push_back(c);
  }
  return closure;
}

struct Sending {
  long sent = 0;
  double seconds = 0.0;     // from the first keyframe to after the last
  ros::WallTime last_sent;  // after the last keyframe
};

Sending sendKeyframes(const Options& opt, const Run& run, const ros::Publisher& odom_pub,
                      const ros::Publisher& loop_pub, const BackendStatus& status) {
  // A detector answers a keyframe after its odometry has arrived: the LoopClosure follows a little later.
  const ros::WallDuration lead(std::min(0.005, 0.25 / opt.rate));
  std::vector<ros::Time> stamps;
  stamps.reserve(run.truth.size());
  ros::WallRate rate(opt.rate);
  const ros::WallTime start = ros::WallTime::now();
  long sent = 0;
  for (size_t k = 0; k < run.truth.size() && ros::ok(); ++k) {
    const ros::Time stamp = ros::Time::now();
    stamps.push_back(stamp);
    odom_pub.publish(odometryMsg(stamp, run.odometry[k]));
    lead.sleep();

    loop_pub.publish(loopClosureMsg(run, k, stamp, stamps));
    ++sent;

    if (sent % opt.sample_every == 0) {
      if (const auto s = status.latest()) printRow(sent, *s);
    }
    rate.sleep();
  }
  const ros::WallTime last_sent = ros::WallTime::now();
  return {sent, (last_sent - start).toSec(), last_sent};
}

// Settled: a status from after the last keyframe (the updater reports every second) with none
// waiting, and every keyframe received, or the received count unchanged for 3 s (the rest is lost).
void waitUntilSettled(const Options& opt, const Sending& sending, const BackendStatus& status) {
  const ros::WallTime settle_end = sending.last_sent + ros::WallDuration(opt.settle);
  long long last_received = -1;
  ros::WallTime received_since = ros::WallTime::now();
  std::optional<Status> final_status;
  ros::WallTime arrived;
  while (ros::ok() && ros::WallTime::now() < settle_end) {
    final_status = status.latest(&arrived);
    const long long received = count(*final_status, "keyframes received");
    if (received != last_received) {
      last_received = received;
      received_since = ros::WallTime::now();
    }
    const bool fresh = arrived > sending.last_sent + ros::WallDuration(1.0);
    if (fresh && count(*final_status, "keyframes waiting") == 0 &&
        (received == sending.sent || (ros::WallTime::now() - received_since).toSec() > 3.0)) {
      break;
    }
    ros::WallDuration(0.1).sleep();
  }
}

// The back-end's account of the keyframes; -1 for a missing entry.
struct KeyframeCounts {
  long long received, in_graph, waiting, dropped;
};

KeyframeCounts keyframeCounts(const Status& s) {
  return {count(s, "keyframes received"), count(s, "keyframes in graph"), count(s, "keyframes waiting"),
          count(s, "keyframes dropped")};
}

void printSummary(const Run& run, const Sending& sending, const Status& s, const ros::WallTime& arrived) {
  const KeyframeCounts c = keyframeCounts(s);
  const double silent_s = (ros::WallTime::now() - arrived).toSec();
  std::printf("\nsent %ld keyframes in %.1f s (%.1f Hz), %zu of %zu with a loop\n", sending.sent, sending.seconds,
              sending.sent / sending.seconds, run.loops, run.truth.size());
  std::printf("back-end: received %lld, in graph %lld, waiting %lld, dropped %lld (%s)\n", c.received, c.in_graph,
              c.waiting, c.dropped, dropCauses(s).c_str());
  std::printf("rejected: odometry %s, tf %s; loops kept %s, rejected %s, refused %s, skipped %s\n",
              text(s, "odometry rejected").c_str(), text(s, "tf rejected").c_str(), text(s, "loops kept").c_str(),
              text(s, "loops rejected").c_str(), text(s, "loops refused").c_str(), text(s, "loops skipped").c_str());
  std::printf(
      "solves %s (failed %s), chains %s; update ms median %s, p95 %s (last 1000 updates), last update %s "
      "keyframes\n",
      text(s, "solves").c_str(), text(s, "solves failed").c_str(), text(s, "chains").c_str(),
      text(s, "update ms median").c_str(), text(s, "update ms p95").c_str(), text(s, "update keyframes").c_str());
  if (silent_s > 5.0) {
    std::printf("the back-end's diagnostics stopped %.0f s ago: did its nodelet manager die?\n", silent_s);
  }
}

// Whether the back-end received every keyframe sent and accounts for each; prints FAIL lines or OK.
bool checkAccounting(long sent, const Status& s) {
  const KeyframeCounts c = keyframeCounts(s);
  bool ok = true;
  if (c.received != sent) {
    std::printf("FAIL: the back-end received %lld of %ld keyframes (the rest were lost before it counted them)\n",
                c.received, sent);
    ok = false;
  }
  if (c.received < 0 || c.in_graph < 0 || c.waiting < 0 || c.dropped < 0 ||
      c.received != c.in_graph + c.waiting + c.dropped) {
    std::printf("FAIL: received %lld != in graph %lld + waiting %lld + dropped %lld\n", c.received, c.in_graph,
                c.waiting, c.dropped);
    ok = false;
  }
  if (ok) std::printf("OK: every keyframe received and accounted for\n");
  return ok;
}

int run(const Options& opt) {
  ros::NodeHandle nh;
  if (ros::Time::isSimTime()) throw mild::InvalidInput("/use_sim_time is set: the benchmark paces by the wall clock");
  const Run run = makeRun(opt);
  // Queues as long as the run: whatever is lost, the back-end lost.
  const uint32_t queue = static_cast<uint32_t>(std::min(opt.keyframes, 100000));
  ros::Publisher odom_pub = nh.advertise<nav_msgs::Odometry>("odom", queue);
  ros::Publisher loop_pub = nh.advertise<mild_lcd::LoopClosure>("loop_closure", queue);
  BackendStatus status;
  ros::AsyncSpinner spinner(1);
  spinner.start();

  waitForBackend(odom_pub, loop_pub, status);
  printIntro(opt, run);
  const Sending sending = sendKeyframes(opt, run, odom_pub, loop_pub, status);
  waitUntilSettled(opt, sending, status);
  ros::WallTime arrived;
  const std::optional<Status> final_status = status.latest(&arrived);
  const Status& s = *final_status;
  printRow(sending.sent, s);
  printSummary(run, sending, s, arrived);
  const bool ok = checkAccounting(sending.sent, s);
  std::fflush(stdout);
  spinner.stop();
  return ok ? 0 : mild::tools::kExitFailure;
}

}  // namespace

int main(int argc, char** argv) {
  // Removes the ROS arguments (remappings, __name:=) before the options are parsed.
  ros::init(argc, argv, "mild_bench_backend");
  CLI::App app{
      "Feed the example back-end (mild_lcd/PoseGraphNodelet) synthetic keyframes, odometry and loops at a fixed "
      "rate and report from its diagnostics whether it keeps up and accounts for every keyframe."};
  app.name("mild_bench_backend");
  Options opt;
  CLI::Option* keyframes = app.add_option("--keyframes", opt.keyframes, "keyframes to send (or ~keyframes)")
                               ->check(CLI::PositiveNumber)
                               ->capture_default_str();
  CLI::Option* rate = app.add_option("--rate", opt.rate, "keyframes per second, wall clock (or ~rate)")
                          ->check(CLI::PositiveNumber)
                          ->capture_default_str();
  app.add_option("--sample-every", opt.sample_every, "a diagnostics row every this many keyframes")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--settle", opt.settle, "seconds to wait at the end for the back-end to settle")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--seed", opt.seed, "seed of the odometry's drift")->capture_default_str();
  return mild::tools::toolMain(app, argc, argv, [&] {
    // The private parameters, where no option was given (a launch file sets those).
    ros::NodeHandle pnh("~");
    if (keyframes->count() == 0) pnh.param("keyframes", opt.keyframes, opt.keyframes);
    if (rate->count() == 0) pnh.param("rate", opt.rate, opt.rate);
    if (opt.keyframes < 1) throw mild::InvalidInput("~keyframes must be at least 1");
    if (!(opt.rate > 0.0) || !std::isfinite(opt.rate)) throw mild::InvalidInput("~rate must be above 0");
    return run(opt);
  });
}
