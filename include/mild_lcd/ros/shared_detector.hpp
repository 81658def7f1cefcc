#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "mild_lcd/detector/robot_team.hpp"

namespace mild_lcd {

// The robots' detectors and the lock every user takes: the worker for one keyframe at a time,
// services for as little as they can (copying features, swapping a prepared map in). Nothing slow
// is done while holding it except a save, which streams the state to disk. One robot (the usual
// node) is a team of one, named "".
struct SharedDetector {
  std::mutex mutex;
  std::unique_ptr<mild::RobotTeam> team;
  // Per robot: set when its map named at start-up could not be loaded. Its keyframes and map
  // services are refused (saying why), so that nothing is learnt on an empty map that a save could
  // then write over it. Under mutex.
  std::vector<std::string> failure;

  mild::LoopDetector& robot(size_t r) { return team->robot(r); }
  void setTeam(std::unique_ptr<mild::RobotTeam> t) {
    team = std::move(t);
    failure.assign(team->size(), "");
  }
};

}  // namespace mild_lcd
