#pragma once

// Several robots, one map. Each robot's keyframes go into a LoopDetector of their own: its sessions,
// temporal exclusion, near-past band and temporal filter are the robot's, so every robot's own loops
// are found exactly as a lone detector finds them. Each keyframe is also looked up in other robots'
// maps (detector/other_maps_per_keyframe of them, in turn: the work per keyframe does not grow with
// the team), through a temporal filter per ordered pair of robots (robot A's keyframes against
// robot B's map): the filter's motion model needs neighbouring map entries to be neighbouring places
// and its queries to be one robot's consecutive keyframes, which holds within a pair and would not
// for the robots' keyframes interleaved in one map. The robot's detector runs its one pipeline over
// its own map and these (LoopDetector::process with OtherMap): inter-robot candidates are verified,
// scored and ranked with the robot's own, max_candidates bounds them all together, and
// LoopCandidate::robot tells which map a candidate is in. The pair filters are not saved with the
// maps (database_file.hpp says why).

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/detector/observation.hpp"

namespace mild {

class RobotTeam {
 public:
  // Throws InvalidInput for invalid parameters, no robot, an empty name or a name given twice. One
  // robot (any name) is a lone LoopDetector.
  RobotTeam(const DetectorParams& params, std::vector<std::string> names);
  // A team of one, around a detector that exists already (with what it has learnt).
  explicit RobotTeam(std::unique_ptr<LoopDetector> robot, std::string name = "");

  size_t size() const { return robots_.size(); }
  const std::string& name(size_t robot) const { return names_.at(robot); }
  const std::vector<std::string>& names() const { return names_; }
  std::optional<size_t> find(const std::string& name) const;
  LoopDetector& robot(size_t robot) { return *robots_.at(robot); }
  const LoopDetector& robot(size_t robot) const { return *robots_.at(robot); }
  const DetectorParams& params() const { return robots_.front()->params(); }

  // A keyframe of observation.robot (its features: images go through a FeatureFrontEnd first), as
  // LoopDetector::process, with the other robots' maps asked too: result.query_robot = the robot,
  // each candidate's robot its map's, at most max_candidates in all. Throws InvalidInput (changing
  // nothing) for a robot out of range and whatever the robot's detector refuses.
  DetectionResult process(Observation observation);

  // Whether the maps, while every one is empty, take the descriptor width of the first keyframe
  // given (LoopDetector::takeWidth): for a node fed a front-end's own descriptors only. Off by
  // default; a team across hosts keeps it off (its messages carry the width fixed at start-up).
  void takeWidthFromFirstKeyframe(bool on) { takes_first_width_ = on; }
  bool takesWidthFromFirstKeyframe() const { return takes_first_width_; }
  // With it on and every map empty: every map takes `bytes` (LoopDetector::takeWidth), as before a
  // map of that width is loaded. Returns whether they changed; throws InvalidInput as takeWidth.
  bool takeWidth(int bytes);
  int descriptorBytes() const { return robots_.front()->map().descriptorBytes(); }

  // A keyframe of a robot at another station (team across hosts), known by its summary's
  // descriptors: asked of each of this team's maps, robot r's keyframes [0, eligible[r]) (whose
  // station decides: StationLedger), each through a filter of the pair (remote robot, r). Changes
  // only those filters. The candidates are not yet verified; needs_features says whether verifying
  // any could change a decision (else judgeRemote without features decides the same).
  struct RemoteAnswer {
    std::vector<LoopCandidate> candidates;
    std::vector<size_t> maps;  // the robot whose map holds candidates[i]
    bool needs_features = false;
    StepStats stats;
  };
  // Throws InvalidInput for an eligible list of the wrong size, or for more than kMaxRemoteRobots
  // remote robots.
  RemoteAnswer askRemote(const std::string& remote_robot, const DescriptorList& descriptors, size_t features,
                         const std::vector<KeyframeIndex>& eligible);
  // Verifies answer's candidates against the keyframe's whole features (nullptr: not fetched,
  // none verified), scores and ranks them, at most max_candidates. The maps must not have been
  // replaced since askRemote (they may have grown). query_robot is left 0: the query is remote.
  DetectionResult judgeRemote(RemoteAnswer answer, const Features* features) const;
  // A remote robot began a new session (its station restarted on its saved maps, it was moved): its
  // next keyframes do not follow its last ones, and its filters into this team's maps start over.
  void remoteSessionBegan(const std::string& remote_robot);
  static constexpr size_t kMaxRemoteRobots = 256;
  size_t remoteRobots() const { return remote_filters_.size(); }

  // After robot's map was replaced, reset or merged (a load, a reset): the pair filters that look
  // at it or from it start over from "no loop", since their hypotheses were its old keyframes.
  void mapChanged(size_t robot);
  void reset();  // every robot's map and every filter
  // LoopDetector::retune for every robot (all or nothing: the first refusal changes none).
  void retune(const DetectorParams& next);
  uint64_t retunes() const { return robots_.front()->retunes(); }

  // The other robots whose maps robot's next keyframe will be looked up in
  // (detector/other_maps_per_keyframe of them, in turn).
  std::vector<size_t> mapsAskedNext(size_t robot) const;

  size_t keyframes() const;
  size_t features() const;
  size_t memoryBytes() const;

 private:
  // The maps robot's next keyframe is looked up in besides its own, each through its pair filter:
  // detector/other_maps_per_keyframe of them, in turn.
  std::vector<OtherMap> otherMaps(size_t robot);
  TemporalFilter& pairFilter(size_t from, size_t to) { return *pair_filters_[from * robots_.size() + to]; }

  std::vector<std::string> names_;
  bool takes_first_width_ = false;
  std::vector<std::unique_ptr<LoopDetector>> robots_;
  std::vector<std::unique_ptr<TemporalFilter>> pair_filters_;  // [from * size() + to], none for from == to
  // Per remote robot ("station/robot"): its filter into each of this team's maps.
  std::map<std::string, std::vector<std::unique_ptr<TemporalFilter>>> remote_filters_;
};

}  // namespace mild
