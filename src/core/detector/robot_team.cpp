#include "mild_lcd/detector/robot_team.hpp"

#include <chrono>
#include <set>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stopwatch.hpp"

namespace mild {

RobotTeam::RobotTeam(const DetectorParams& params, std::vector<std::string> names) : names_(std::move(names)) {
  if (names_.empty()) throw InvalidInput("a robot team needs at least one robot");
  std::set<std::string> seen;
  for (const std::string& n : names_) {
    if (names_.size() > 1 && n.empty()) throw InvalidInput("robot names must not be empty");
    if (!seen.insert(n).second) throw InvalidInput("robot '" + n + "' is named twice");
  }
  for (size_t r = 0; r < names_.size(); ++r) robots_.push_back(std::make_unique<LoopDetector>(params));
  pair_filters_.resize(names_.size() * names_.size());
  for (size_t from = 0; from < names_.size(); ++from) {
    for (size_t to = 0; to < names_.size(); ++to) {
      if (from != to) pair_filters_[from * names_.size() + to] = makeTemporalFilter(params.filter);
    }
  }
}

RobotTeam::RobotTeam(std::unique_ptr<LoopDetector> robot, std::string name) : names_{std::move(name)} {
  if (!robot) throw InvalidInput("a robot team needs a detector");
  robots_.push_back(std::move(robot));
  pair_filters_.resize(1);
}

std::optional<size_t> RobotTeam::find(const std::string& name) const {
  for (size_t r = 0; r < names_.size(); ++r) {
    if (names_[r] == name) return r;
  }
  return std::nullopt;
}

DetectionResult RobotTeam::process(size_t robot, Features features, double stamp, std::optional<uint64_t> id) {
  if (robot >= robots_.size()) throw InvalidInput("no robot " + std::to_string(robot));
  const std::vector<float> depths = features.depths;
  DetectionResult result = robots_[robot]->process(std::move(features), stamp, id);
  addOtherRobots(robot, result, depths);
  return result;
}

DetectionResult RobotTeam::process(size_t robot, const cv::Mat& image, PixelFormat format, double stamp,
                                   std::optional<uint64_t> id, const CameraIntrinsics& camera) {
  if (robot >= robots_.size()) throw InvalidInput("no robot " + std::to_string(robot));
  DetectionResult result = robots_[robot]->process(image, format, stamp, id, camera);
  addOtherRobots(robot, result, {});
  return result;
}

void RobotTeam::addOtherRobots(size_t robot, DetectionResult& result, const std::vector<float>& depths) {
  result.query_robot = static_cast<uint32_t>(robot);
  for (LoopCandidate& c : result.candidates) c.robot = static_cast<uint32_t>(robot);
  if (robots_.size() == 1) return;
  const LoopDetector& own = *robots_[robot];
  const DescriptorList query = own.database().descriptors(result.query_index);
  for (size_t other = 0; other < robots_.size(); ++other) {
    const LoopDetector& map = *robots_[other];
    if (other == robot || map.size() == 0) continue;
    // Another robot's keyframes are never "a moment ago": all of them, no exclusion, no band.
    auto start = Clock::now();
    const QueryResult q = map.database().query(query, kAllKeyframes, map.params().search);
    result.stats.query_ms += msSince(start);
    result.stats.query += q.stats;
    start = Clock::now();
    const std::vector<double>& belief = pairFilter(robot, other).update(q.similarity);
    result.stats.filter_ms += msSince(start);
    start = Clock::now();
    std::vector<LoopCandidate> found = own.candidatesIn(map, belief, q.similarity, result.query_index, depths);
    result.stats.verify_ms += msSince(start);
    for (LoopCandidate& c : found) {
      c.robot = static_cast<uint32_t>(other);
      result.candidates.push_back(std::move(c));
    }
  }
  rankCandidates(result.candidates, own.params().candidates.min_probability);
}

void RobotTeam::mapChanged(size_t robot) {
  for (size_t other = 0; other < robots_.size(); ++other) {
    if (other == robot) continue;
    pairFilter(robot, other).reset();
    pairFilter(other, robot).reset();
  }
}

void RobotTeam::reset() {
  for (auto& r : robots_) r->reset();
  for (auto& f : pair_filters_) {
    if (f) f->reset();
  }
}

void RobotTeam::retune(const DetectorParams& next) {
  robots_.front()->retune(next);  // refuses, changing nothing, what any robot would refuse
  for (size_t r = 1; r < robots_.size(); ++r) robots_[r]->retune(next);
}

size_t RobotTeam::keyframes() const {
  size_t n = 0;
  for (const auto& r : robots_) n += r->size();
  return n;
}

size_t RobotTeam::features() const {
  size_t n = 0;
  for (const auto& r : robots_) n += r->database().featureCount();
  return n;
}

size_t RobotTeam::memoryBytes() const {
  size_t n = 0;
  for (const auto& r : robots_) n += r->memoryBytes();
  return n;
}

}  // namespace mild
