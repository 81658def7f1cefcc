#include "mild_lcd/detector/robot_team.hpp"

#include <algorithm>
#include <set>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/filter/filters.hpp"

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
  if (robot >= robots_.size()) throw InvalidInput("no robot " + std::to_string(robot));
  if (takes_first_width_ && !observation.image) {
    const Features& f = observation.features;
    takeWidth(f.declared_bytes != 0 ? f.declared_bytes : f.descriptors.empty() ? 0 : f.descriptors.front().bytes);
  }
  const std::vector<OtherMap> others = otherMaps(robot);
  return robots_[robot]->process(std::move(observation), others, static_cast<uint32_t>(robot));
}

bool RobotTeam::takeWidth(int bytes) {
  if (!takes_first_width_ || bytes == 0 || keyframes() > 0 || bytes == descriptorBytes()) return false;
  // All maps at once: a keyframe is looked up in the other robots' maps too, which must hold its
  // width. The first throws for parameters that do not hold at it, before any map changed.
  for (auto& detector : robots_) detector->takeWidth(bytes);
  return true;
}

RobotTeam::RemoteAnswer RobotTeam::askRemote(const std::string& remote_robot, const DescriptorList& descriptors,
                                             size_t features, const std::vector<KeyframeIndex>& eligible) {
  if (eligible.size() != robots_.size()) throw InvalidInput("one eligible prefix per robot is needed");
  auto it = remote_filters_.find(remote_robot);
  if (it == remote_filters_.end()) {
    if (remote_filters_.size() >= kMaxRemoteRobots) {
      throw InvalidInput("more than " + std::to_string(kMaxRemoteRobots) + " remote robots");
    }
    std::vector<std::unique_ptr<TemporalFilter>> filters;
    for (size_t r = 0; r < robots_.size(); ++r) filters.push_back(makeTemporalFilter(params().filter));
    it = remote_filters_.emplace(remote_robot, std::move(filters)).first;
  }
  RemoteAnswer answer;
  const size_t max_candidates = static_cast<size_t>(params().candidates.max_candidates);
  for (size_t r = 0; r < robots_.size(); ++r) {
    const KeyframeMap& map = robots_[r]->map();
    const KeyframeIndex in_scope = std::min<KeyframeIndex>(eligible[r], static_cast<KeyframeIndex>(map.size()));
    if (in_scope == 0) continue;
    MapScope scope;
    scope.eligible = in_scope;
    MapAnswer a = robots_[r]->queryMap(map, descriptors, scope, *it->second[r], max_candidates);
    answer.stats.query_ms += a.query_ms;
    answer.stats.filter_ms += a.filter_ms;
    answer.stats.query += a.query.stats;
    answer.stats.eligible_keyframes += a.query.similarity.size();
    for (LoopCandidate& c : a.candidates) {
      c.robot = static_cast<uint32_t>(r);
      const int matches = static_cast<int>(std::min(features, map.record(c.index).keypoints.size()));
      answer.needs_features = answer.needs_features || robots_[r]->couldBeAccepted(c, matches);
      answer.candidates.push_back(std::move(c));
      answer.maps.push_back(r);
    }
  }
  answer.stats.features = features;
  return answer;
}

DetectionResult RobotTeam::judgeRemote(RemoteAnswer answer, const Features* features) const {
  DetectionResult result;
  std::vector<const KeyframeMap*> maps;
  for (size_t r : answer.maps) maps.push_back(&robots_.at(r)->map());
  robots_.front()->judge(answer.candidates, features, maps);
  const size_t max_candidates = static_cast<size_t>(params().candidates.max_candidates);
  if (answer.candidates.size() > max_candidates) answer.candidates.resize(max_candidates);
  result.candidates = std::move(answer.candidates);
  result.stats = answer.stats;
  return result;
}

void RobotTeam::remoteSessionBegan(const std::string& remote_robot) {
  const auto it = remote_filters_.find(remote_robot);
  if (it == remote_filters_.end()) return;
  for (auto& f : it->second) f->reset();
}

void RobotTeam::mapChanged(size_t robot) {
  for (size_t other = 0; other < robots_.size(); ++other) {
    if (other == robot) continue;
    pairFilter(robot, other).reset();
    pairFilter(other, robot).reset();
  }
  for (auto& [remote, filters] : remote_filters_) filters.at(robot)->reset();
}

void RobotTeam::reset() {
  for (auto& r : robots_) r->map().reset();
  for (auto& f : pair_filters_) {
    if (f) f->reset();
  }
  for (auto& [remote, filters] : remote_filters_) {
    for (auto& f : filters) f->reset();
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
  // The filters between maps each hold a state as long as the map they look into.
  for (const auto& f : pair_filters_) n += f ? f->memoryBytes() : 0;
  for (const auto& [remote, filters] : remote_filters_) {
    for (const auto& f : filters) n += f->memoryBytes();
  }
  return n;
}

}  // namespace mild
