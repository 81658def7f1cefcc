#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "mild_lcd/detector/robot_team.hpp"

namespace mild_lcd {

// The robots' detectors and the lock every user takes: the worker for one keyframe at a time,
// services for as little as they can (copying features, swapping a prepared map in). Nothing slow
// is done while holding it except a save, which streams the state to disk, and a merge, which
// rebuilds the index. One robot (the usual node) is a team of one, named "".
struct SharedDetector {
  std::mutex mutex;
  std::unique_ptr<mild::RobotTeam> team;
  // Per robot: set when its map named at start-up could not be loaded. Its keyframes and map
  // services are refused (saying why), so that nothing is learnt on an empty map that a save could
  // then write over it. Under mutex.
  std::vector<std::string> failure;
  // Bumped by everything that changes a map (a keyframe, a load, a merge, a reset), so that a
  // periodic save writes only what changed. Under mutex.
  uint64_t changes = 0;

  // Bumped by everything that replaces a map's keyframes (a load, a merge, a reset): what was
  // asked of the old keyframes (a team pull in flight) is not judged on the new ones. Under mutex.
  uint64_t replaced = 0;
  // Told, under mutex, of each robot whose map was replaced (the team across hosts renumbers).
  std::function<void(size_t robot)> on_map_replaced;

  // The one place maps change other than by a keyframe: the team's filters that looked at the old
  // keyframes start over (RobotTeam::mapChanged), `replaced` and `changes` move, listeners are
  // told. Under mutex, after the map was loaded or merged. `unsaved`: false when the map is what a
  // file holds (loaded at start-up): `changes` stays, so no save follows.
  void mapReplaced(size_t robot, bool unsaved = true);
  // Empties every map (RobotTeam::reset), the same way. Under mutex.
  void resetMaps();

  mild::LoopDetector& robot(size_t r) { return team->robot(r); }
  void setTeam(std::unique_ptr<mild::RobotTeam> t) {
    team = std::move(t);
    failure.assign(team->size(), "");
  }

  // Takes the lock, then applies a retune that arrived while someone else held it. Every user of
  // the detector locks through here (or tryLock), so a retune is in force before anything reads the
  // parameters it changes.
  std::unique_lock<std::mutex> lock();
  // The same without waiting: the lock is not owned when someone else holds it.
  std::unique_lock<std::mutex> tryLock();

  // Live tuning never waits for the detector: `next` (validated by the caller, only runtime
  // parameters changed: RobotTeam::retune cannot refuse it) is applied at once when the lock is
  // free, else by the next holder of the lock, before the next keyframe. A later request replaces
  // one that waits.
  void requestRetune(const mild::DetectorParams& next);
  // Whether a retune waits for the lock (tests).
  bool retunePending();

 private:
  void applyPendingRetune();  // with `mutex` held

  std::mutex retune_mutex_;  // guards pending_retune_ only; never held while waiting for `mutex`
  std::optional<mild::DetectorParams> pending_retune_;
};

}  // namespace mild_lcd
