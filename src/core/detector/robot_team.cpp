#include "mild_lcd/detector/robot_team.hpp"

#include <set>

#include "mild_lcd/common/errors.hpp"

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

std::vector<size_t> RobotTeam::mapsAskedNext(size_t robot) const {
  if (robot >= robots_.size()) throw InvalidInput("no robot " + std::to_string(robot));
  const size_t n_others = robots_.size() - 1;
  const size_t per_keyframe = static_cast<size_t>(params().candidates.other_maps_per_keyframe);
  const size_t asked = per_keyframe == 0 ? n_others : std::min(per_keyframe, n_others);
  // In turn: the robot's n-th keyframe asks the other maps n * asked, n * asked + 1, ... (mod their
  // number), so that each is asked equally often and at regular intervals, which the pair filter's
  // motion model (a revisit moves along the other map by a bounded step per query) tolerates.
  const size_t first = asked == n_others ? 0 : (robots_[robot]->map().size() * asked) % n_others;
  std::vector<size_t> maps;
  for (size_t j = 0; j < asked; ++j) {
    size_t other = (first + j) % n_others;
    if (other >= robot) ++other;  // the other robots, skipping this one
    maps.push_back(other);
  }
  return maps;
}

std::vector<OtherMap> RobotTeam::otherMaps(size_t robot) {
  std::vector<OtherMap> others;
  for (size_t other : mapsAskedNext(robot)) {
    others.push_back({&robots_[other]->map(), &pairFilter(robot, other), static_cast<uint32_t>(other)});
  }
  return others;
}

DetectionResult RobotTeam::process(Observation observation) {
  const size_t robot = observation.robot;
  const std::vector<OtherMap> others = otherMaps(robot);
  return robots_[robot]->process(std::move(observation), others, static_cast<uint32_t>(robot));
}

void RobotTeam::mapChanged(size_t robot) {
  for (size_t other = 0; other < robots_.size(); ++other) {
    if (other == robot) continue;
    pairFilter(robot, other).reset();
    pairFilter(other, robot).reset();
  }
}

void RobotTeam::reset() {
  for (auto& r : robots_) r->map().reset();
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
  for (const auto& r : robots_) n += r->map().size();
  return n;
}

size_t RobotTeam::features() const {
  size_t n = 0;
  for (const auto& r : robots_) n += r->map().database().featureCount();
  return n;
}

size_t RobotTeam::memoryBytes() const {
  size_t n = 0;
  for (const auto& r : robots_) n += r->map().memoryBytes();
  return n;
}

}  // namespace mild
