#pragma once

// Where maps are saved and loaded, and when: the ~database_dir confinement, ~load_on_start,
// ~save_on_shutdown and the save_database / load_database services. ROS-free.

#include <atomic>
#include <cstdint>
#include <string>

#include "mild_lcd/io/database_directory.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "mild_lcd/ros/detection/shared_detector.hpp"
#include "mild_lcd/ros/settings/node_settings.hpp"

namespace mild_lcd {

// The maps of one robot of the team (robot 0: the only one of a usual node). With several robots,
// robot N's ~database_path is the same file name in a folder N beside it (maps/site.mild ->
// maps/N/site.mild), so that ~load_on_start and ~save_on_shutdown keep one map per robot.
class DatabaseStore {
 public:
  // Creates ~database_dir when absent and checks that the robot's ~database_path lies inside it.
  // Throws mild::InvalidInput or mild::IoError.
  explicit DatabaseStore(const NodeSettings& settings, size_t robot = 0, const std::string& robot_name = "");
  const std::string& databasePath() const { return database_path_; }
  const std::string& directory() const { return directory_.root(); }

  // ~load_on_start: loads ~database_path as a new session (a missing file starts an empty map).
  // On any failure the file is left as it is and protected (databaseProtected), shared.failure says
  // why (keyframes are refused until a map is loaded by hand), and the error is rethrown. Returns a
  // line for the log.
  std::string loadOnStart(SharedDetector& shared);

  // The services. `requested` empty means ~database_path. Names resolve inside ~database_dir or are
  // refused; loading reads and rebuilds the index without the detector lock, then swaps it in.
  // Throw mild::Error with a message fit for the reply; the detector is unchanged on failure. Until
  // loadOnStart has run (with ~load_on_start), all three are refused and autosave and
  // saveOnShutdown save nothing: the map is still empty, and the services are up before the worker
  // loads it (several robots load one after another). While
  // ~database_path is protected, a save to it must name it (`requested` not empty): that is the
  // user's explicit decision to replace it, and lifts the protection.
  std::string save(SharedDetector& shared, const std::string& requested);
  mild::LoadReport load(SharedDetector& shared, const std::string& requested, bool continue_session);
  // Adds a saved map to the running one (KeyframeMap::merge). The file is read without the lock;
  // the merge itself holds it while the index is rebuilt (keyframes wait in the queue meanwhile).
  mild::LoadReport merge(SharedDetector& shared, const std::string& requested);

  // ~save_on_shutdown, unless ~database_path is protected. Returns what happened (empty: nothing to
  // do).
  std::string saveOnShutdown(SharedDetector& shared);
  // ~autosave_period: as saveOnShutdown, but only when the maps changed (SharedDetector::changes)
  // since this store's last save to ~database_path. Returns what happened (empty: nothing to do).
  std::string autosave(SharedDetector& shared);
  // Whether ~database_path holds a map that failed to load at start-up, which nothing but the user's
  // explicit word may replace: not autosave, not save_on_shutdown, not a save_database without a
  // path, whatever map was loaded by hand meanwhile (a map over ~max_database_mb, an unreadable
  // one: the user may fix the cause and restart). Lifted by a save_database that names the file,
  // or by loading that very file by hand (the running map then holds it).
  bool databaseProtected() const { return database_protected_; }

 private:
  mild::ConfinedFile resolve(const std::string& requested, bool for_saving) const;

  mild::LoopDetector& detector(SharedDetector& shared) const { return shared.robot(robot_); }
  std::string& failure(SharedDetector& shared) const { return shared.failure.at(robot_); }
  std::string protectionNotice() const;  // why ~database_path is not saved to, and how to
  // Reads `file` and prepares it without the lock, on an empty map of the robot's parameters (the
  // maps, empty and fed a front-end's own descriptors, first take the file's width:
  // RobotTeam::takeWidth); commit holds the lock and refuses a map whose width changed meanwhile.
  mild::PreparedLoad prepare(SharedDetector& shared, const mild::ConfinedFile& file, bool continue_session);
  void commit(SharedDetector& shared, mild::PreparedLoad&& prepared);  // hold the lock

  size_t robot_;
  mild::DatabaseDirectory directory_;
  std::string database_path_;
  bool load_on_start_;
  bool save_on_shutdown_;
  unsigned long long max_bytes_;
  std::atomic<bool> database_protected_{false};
  std::atomic<bool> start_up_pending_{false};  // ~load_on_start and loadOnStart has not run yet
  void refuseWhileStartingUp() const;
  std::string database_display_;  // ~database_path as resolved ("" when not set)
  // SharedDetector::changes when ~database_path last held the map (start: nothing learnt yet, or
  // what the file holds). Under the detector lock.
  uint64_t saved_changes_ = 0;
};

}  // namespace mild_lcd
