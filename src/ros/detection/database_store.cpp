#include "mild_lcd/ros/detection/database_store.hpp"

#include <chrono>
#include <filesystem>
#include <optional>

#include "mild_lcd/common/errors.hpp"

namespace mild_lcd {
namespace {

std::string robotPath(const std::string& path, const std::string& robot) {
  if (path.empty() || robot.empty()) return path;
  const std::filesystem::path p(path);
  return (p.parent_path() / robot / p.filename()).string();
}

mild::DirectoryLimits directoryLimits(const NodeSettings& settings) {
  mild::DirectoryLimits limits;
  limits.max_entries = static_cast<size_t>(settings.max_database_files);
  limits.max_bytes = static_cast<unsigned long long>(settings.max_database_dir_mb) << 20;
  return limits;
}

}  // namespace

DatabaseStore::DatabaseStore(const NodeSettings& settings, size_t robot, const std::string& robot_name)
    : robot_(robot),
      directory_(settings.database_dir, directoryLimits(settings)),
      database_path_(robotPath(settings.database_path, robot_name)),
      load_on_start_(settings.load_on_start),
      save_on_shutdown_(settings.save_on_shutdown),
      max_bytes_(static_cast<unsigned long long>(settings.max_database_mb) << 20),
      start_up_pending_(settings.load_on_start) {
  if (!database_path_.empty()) {
    try {
      // A robot's folder (~robots) is made when its map will be saved: a first start finds it.
      database_display_ = resolve(database_path_, save_on_shutdown_).display();
    } catch (const mild::Error& e) {
      throw mild::InvalidInput(std::string("parameter ~database_path: ") + e.what());
    }
  }
}

mild::ConfinedFile DatabaseStore::resolve(const std::string& requested, bool for_saving) const {
  const std::string& name = requested.empty() ? database_path_ : requested;
  if (name.empty()) throw mild::InvalidInput("no path given and no ~database_path set");
  return directory_.resolve(name, for_saving);
}

std::string DatabaseStore::loadOnStart(SharedDetector& shared) {
  if (!load_on_start_) return "";
  try {
    const mild::ConfinedFile file = resolve("", false);
    if (!file.exists()) {
      start_up_pending_ = false;
      return "database " + file.display() + " does not exist yet: starting with an empty map";
    }
    mild::PreparedLoad prepared = prepare(shared, file, false);
    const std::string message = prepared.report.message;
    const auto lock = shared.lock();
    commit(shared, std::move(prepared));
    shared.mapReplaced(robot_, false);  // the file holds it: no change to save
    start_up_pending_ = false;
    return message;
  } catch (const std::exception& e) {
    database_protected_ = true;
    const auto lock = shared.lock();
    failure(shared) = std::string("the map ~database_path could not be loaded at start-up (") + e.what() +
                      "); the file is left untouched and nothing will be saved over it";
    start_up_pending_ = false;
    throw;
  }
}

mild::PreparedLoad DatabaseStore::prepare(SharedDetector& shared, const mild::ConfinedFile& file,
                                          bool continue_session) {
  const auto start = std::chrono::steady_clock::now();
  mild::MapState state = mild::readMapFile(file, max_bytes_);
  std::optional<mild::KeyframeMap> empty;
  {
    const auto lock = shared.lock();
    shared.team->takeWidth(state.descriptor_bytes);
    empty.emplace(detector(shared).map().emptyLike());
  }
  // The index is rebuilt without the lock: keyframes go on meanwhile.
  return mild::prepareLoad(*empty, std::move(state), file.display(), continue_session, start);
}

void DatabaseStore::commit(SharedDetector& shared, mild::PreparedLoad&& prepared) {
  mild::KeyframeMap& map = detector(shared).map();
  if (prepared.restore.database.descriptorBytes() != map.descriptorBytes()) {
    throw mild::InvalidInput("a keyframe of " + std::to_string(map.descriptorBytes()) +
                             "-byte descriptors was taken while the map was loading: load it again");
  }
  mild::commitLoad(map, std::move(prepared));
}

void DatabaseStore::refuseWhileStartingUp() const {
  if (start_up_pending_) {
    throw mild::InvalidInput("the map ~database_path is still being loaded at start-up: ask again when it is");
  }
}

std::string DatabaseStore::protectionNotice() const {
  return "the map " + database_display_ +
         " failed to load at start-up and is protected: nothing is saved over it unless a save_database request "
         "names it (path: " +
         database_display_ + ")";
}

std::string DatabaseStore::save(SharedDetector& shared, const std::string& requested) {
  const mild::ConfinedFile file = resolve(requested, true);
  const bool to_database_path = !database_display_.empty() && file.display() == database_display_;
  const auto lock = shared.lock();
  refuseWhileStartingUp();  // the map is still empty: saved, it would replace the one being loaded
  if (!failure(shared).empty()) throw mild::InvalidInput(failure(shared));
  // A request that names the file is the user's decision; an empty one merely defaults to it.
  if (to_database_path && database_protected_ && requested.empty()) throw mild::InvalidInput(protectionNotice());
  mild::saveMap(detector(shared).map(), file);
  if (to_database_path) {
    saved_changes_ = shared.changes;
    database_protected_ = false;
  }
  return "saved " + std::to_string(detector(shared).map().size()) + " keyframes to " + file.display();
}

std::string DatabaseStore::autosave(SharedDetector& shared) {
  if (!save_on_shutdown_ || database_protected_ || start_up_pending_) return "";
  {
    const auto lock = shared.lock();
    if (saved_changes_ == shared.changes) return "";
  }
  return save(shared, "");
}

mild::LoadReport DatabaseStore::load(SharedDetector& shared, const std::string& requested, bool continue_session) {
  refuseWhileStartingUp();  // the start-up load would replace it as soon as it is in
  const mild::ConfinedFile file = resolve(requested, false);
  mild::PreparedLoad prepared = prepare(shared, file, continue_session);
  mild::LoadReport report = prepared.report;
  const auto lock = shared.lock();
  commit(shared, std::move(prepared));
  shared.mapReplaced(robot_);
  // A map loaded by hand is the user's decision: keyframes are taken again. ~database_path stays
  // protected (what was loaded is not what it holds), unless this was that very file.
  failure(shared).clear();
  if (!database_display_.empty() && file.display() == database_display_) {
    database_protected_ = false;
    saved_changes_ = shared.changes;  // the running map is what the file holds
  }
  if (database_protected_) report.message += "; " + protectionNotice();
  return report;
}

mild::LoadReport DatabaseStore::merge(SharedDetector& shared, const std::string& requested) {
  refuseWhileStartingUp();
  const mild::ConfinedFile file = resolve(requested, false);
  mild::MapState state = mild::readMapFile(file, max_bytes_);
  const auto lock = shared.lock();
  // Merging into the empty map of a failed start-up would save over the map that failed: refused.
  if (!failure(shared).empty()) {
    throw mild::InvalidInput(failure(shared) + "; load_database without merge replaces it");
  }
  shared.team->takeWidth(state.descriptor_bytes);  // an empty map fed a front-end's descriptors: the file's
  mild::LoadReport report = mild::mergeState(detector(shared).map(), std::move(state), file.display());
  shared.mapReplaced(robot_);
  return report;
}

std::string DatabaseStore::saveOnShutdown(SharedDetector& shared) {
  if (!save_on_shutdown_) return "";
  if (database_protected_) return "not saving on shutdown: " + protectionNotice();
  if (start_up_pending_) return "not saving on shutdown: the map ~database_path was never loaded (stopped before)";
  return save(shared, "");
}

}  // namespace mild_lcd
