#include "mild_lcd/ros/settings/node_settings.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <limits>
#include <sstream>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/team/station.hpp"
#include "mild_lcd/team/station_ledger.hpp"

namespace mild_lcd {
namespace {

using mild::InvalidInput;

// The single declaration of the node's settings: name, field, bounds, meaning. Defaults are the
// struct's; bounds are checked as the detector's are (mild::Bounds), with the names given "~".
template <class Settings, class Visit>
void visitSettings(Settings& s, Visit&& visit) {
  using mild::Bounds;
  visit("use_image_input", s.use_image_input, Bounds::any(), "subscribe to `image` (image_transport)");
  visit("use_keyframe_input", s.use_keyframe_input, Bounds::any(),
        "subscribe to `keyframe` (mild_lcd/Keyframe features)");
  visit("image_transport", s.image_transport, Bounds::any(),
        "transport of `image`: raw, compressed, or any installed plugin");
  visit("use_camera_info", s.use_camera_info, Bounds::any(),
        "with image input, take intrinsics from `camera_info` beside `image` (the newest received; "
        "verification/fx.. until one arrives)");
  visit("publish_correspondences", s.publish_correspondences, Bounds::any(),
        "add each verified candidate's inlier matches (keypoint indices and pixels) to `loop_closure`");
  visit("queue_size", s.queue_size, Bounds::in(1, 100000),
        "keyframes waiting for the worker; when full the oldest is dropped and counted (roscpp's queue of each input "
        "has the same length)");
  visit("queue_mb", s.queue_mb, Bounds::in(1, 1 << 20),
        "and at most this many megabytes of messages waiting (a message larger than that is rejected)");
  visit("extraction_thread", s.extraction_thread, Bounds::any(),
        "decode and extract keyframe k+1 on a thread of its own while keyframe k is queried, verified and stored "
        "(on a machine of one core, or false: one thread does both, extracting under the detector lock); answers "
        "keep their order");
  visit("debug_image_cache", s.debug_image_cache, Bounds::in(0, 1000000),
        "keyframes kept at half resolution for `debug_image` (0 = none)");
  visit("debug_image_cache_mb", s.debug_image_cache_mb, Bounds::in(0, 1 << 20),
        "and at most this many megabytes of them");
  visit("max_image_pixels", s.max_image_pixels, Bounds::in(1, 1 << 30),
        "larger images (width x height) are refused before decoding; also bounds their bytes: a raw image's data "
        "(exactly step x height) at most this many pixels of its encoding, a compressed one (JPEG or PNG only, judged "
        "on its header) at most 4 bytes per pixel of it");
  visit("max_keyframe_features", s.max_keyframe_features, Bounds::in(1, 1000000),
        "`Keyframe` messages with more keypoints are refused (they would be stored, and matched whole)");
  visit("database_dir", s.database_dir, Bounds::any(),
        "the only folder maps are saved to and loaded from (default: database_path's folder, else $ROS_HOME/mild_lcd)");
  visit("database_path", s.database_path, Bounds::any(),
        "map file inside database_dir: default of the services, and of load_on_start/save_on_shutdown");
  visit("load_on_start", s.load_on_start, Bounds::any(), "load database_path at start-up, as a new session");
  visit("save_on_shutdown", s.save_on_shutdown, Bounds::any(),
        "save to database_path on shutdown: SIGINT, SIGTERM, unload (never after a failed start-up load)");
  visit("autosave_period", s.autosave_period, Bounds::in(0, 86400),
        "with save_on_shutdown, also save database_path every this many seconds when the map changed (0 = on "
        "shutdown only): SIGKILL, a crash or a power cut loses at most this much");
  visit("max_database_mb", s.max_database_mb, Bounds::in(1, 1 << 24),
        "database files larger than this are refused unread");
  visit("max_database_files", s.max_database_files, Bounds::in(1, 1000000),
        "a save that would add a file or folder to database_dir is refused once it holds this many (names may be "
        "at most 8 folders deep)");
  visit("max_database_dir_mb", s.max_database_dir_mb, Bounds::in(1, 1 << 30),
        "a save is refused once the files in database_dir (but the one it replaces) hold this many megabytes");
  visit("max_match_features", s.max_match_features, Bounds::in(1, 10000000),
        "descriptors per side of a sparse_match request, at most");
  visit("robots", s.robots, Bounds::any(),
        "names of the robots this node serves, space- or comma-separated (`robot1 robot2`): each robot's topics and "
        "services go under its name (`robot1/keyframe`, `robot1/loop_closure`, `robot1/save_database`, ...), "
        "`loop_closures_all` carries every robot's; empty: one robot, names as above");
  visit("team/station", s.team_station, Bounds::any(),
        "this node's name in a team across hosts (1-32 of [a-z0-9_], starting with a letter): it finds the loops "
        "between its robots and other stations' over /mild_team/ topics (docs/multi_robot.md); empty: no team");
  visit("team/summary_bytes", s.team_summary_bytes, Bounds::in(64, 1 << 20),
        "descriptor bytes of the summary pushed to the other stations per keyframe (its strongest descriptors: 7776 "
        "is 243 ORB descriptors, a message under 8 KB)");
  visit("team/backfill_batch", s.team_backfill_batch, Bounds::in(1, 1000),
        "summaries asked for, and sent, per request when a station fills a gap (after a link came back)");
  visit("team/peer_timeout", s.team_peer_timeout, Bounds::in(0.5, 3600),
        "seconds without a peer's heartbeat after which it is reported disconnected");
  visit("team/max_requests_per_second", s.team_max_requests_per_second, Bounds::in(1, 100000),
        "requests served per second to one peer (a burst of twice as many); more are refused as busy and counted");
  visit("team/max_pending_pulls", s.team_max_pending_pulls, Bounds::in(1, 10000),
        "per peer, keyframes waiting for their features to be verified; its next summaries wait until fewer do");
}

template <class T>
std::string toText(const T& v) {
  if constexpr (std::is_same_v<T, std::string>) {
    if (v.empty()) return "\"\"";
  }
  return mild::parameterText(v);
}

}  // namespace

const std::vector<SettingDoc>& nodeSettingDocs() {
  static const std::vector<SettingDoc> docs = [] {
    std::vector<SettingDoc> out;
    NodeSettings defaults;
    visitSettings(defaults, [&](const char* name, auto& field, const mild::Bounds& bounds, const char* doc) {
      out.push_back({name, toText(field), bounds.text(), doc});
    });
    return out;
  }();
  return docs;
}

std::string nodeSettingsMarkdown() {
  std::ostringstream out;
  out << "| parameter | default | range | meaning |\n|---|---|---|---|\n";
  for (const SettingDoc& d : nodeSettingDocs())
    out << "| `~" << d.name << "` | `" << d.default_value << "` | " << d.range << " | " << d.doc << " |\n";
  return out.str();
}

NodeSettings NodeSettings::load(const mild::ParameterSource& source, const std::string& default_dir) {
  NodeSettings s;
  visitSettings(s, [&](const char* name, auto& field, const mild::Bounds&, const char*) {
    mild::readParameter(source, name, field, "~" + std::string(name));
  });
  if (!s.use_image_input && !s.use_keyframe_input) {
    throw InvalidInput("~use_image_input and ~use_keyframe_input are both false: nothing to listen to");
  }
  visitSettings(s, [](const char* name, const auto& field, const mild::Bounds& bounds, const char*) {
    bounds.check(std::string("parameter ~") + name, field);
  });
  const std::vector<std::string> robots = s.robotNames();
  for (size_t i = 0; i < robots.size(); ++i) {
    const std::string& r = robots[i];
    const bool valid =
        std::isalpha(static_cast<unsigned char>(r.front())) &&
        std::all_of(r.begin(), r.end(), [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; });
    if (!valid) {
      throw InvalidInput("parameter ~robots: '" + r + "' is not a robot name (a letter, then letters, digits or _)");
    }
    if (std::find(robots.begin(), robots.begin() + static_cast<long>(i), r) != robots.begin() + static_cast<long>(i)) {
      throw InvalidInput("parameter ~robots names '" + r + "' twice");
    }
  }
  if (!s.team_station.empty() && !mild::validStationName(s.team_station)) {
    throw InvalidInput("parameter ~team/station: '" + s.team_station +
                       "' is not a station name (1-32 of [a-z0-9_], starting with a letter)");
  }
  if (s.image_transport.empty())
    throw InvalidInput("parameter ~image_transport must name a transport (raw, compressed, ...)");

  namespace fs = std::filesystem;
  if ((s.load_on_start || s.save_on_shutdown) && s.database_path.empty()) {
    throw InvalidInput("~load_on_start and ~save_on_shutdown need ~database_path (the database file)");
  }
  if (!s.database_dir.empty() && s.database_dir.front() != '/') {
    throw InvalidInput("parameter ~database_dir must be an absolute path, got '" + s.database_dir + "'");
  }
  if (s.database_dir.empty()) {
    const fs::path path(s.database_path);
    s.database_dir = path.is_absolute() && path.has_parent_path() ? path.parent_path().string() : default_dir;
  }
  return s;
}

std::vector<std::string> NodeSettings::robotNames() const {
  std::vector<std::string> names;
  std::string name;
  for (char c : robots + " ") {
    if (c == ' ' || c == ',' || c == '\t') {
      if (!name.empty()) names.push_back(name);
      name.clear();
    } else {
      name += c;
    }
  }
  return names;
}

mild::StationSettings NodeSettings::stationSettings(std::vector<std::string> robots) const {
  mild::StationSettings out;
  out.station = team_station;
  for (std::string& name : robots) {
    if (name.empty()) name = team_station;
  }
  out.robots = std::move(robots);
  out.summary_bytes = static_cast<size_t>(team_summary_bytes);
  out.backfill_batch = static_cast<size_t>(team_backfill_batch);
  out.max_pending_pulls = static_cast<size_t>(team_max_pending_pulls);
  out.max_requests_per_second = team_max_requests_per_second;
  out.peer_timeout = team_peer_timeout;
  out.max_keyframe_features = static_cast<size_t>(max_keyframe_features);
  return out;
}

std::string extractionCostWarning(const NodeSettings& settings, const std::string& feature_type) {
  constexpr int kCheapPixels = 2048 * 2048;
  if (feature_type == "orb" || !settings.use_image_input || settings.max_image_pixels <= kCheapPixels) return "";
  return "features/type " + feature_type + " on images of up to ~max_image_pixels (" +
         std::to_string(settings.max_image_pixels) +
         ") pixels: extraction grows with the pixels and the keypoints found (AKAZE on noise: 2048 x 2048 took 3 s "
         "and 400 MB, 4096 x 4096 168 s and 1.9 GB), holding the worker meanwhile. Set ~max_image_pixels to the "
         "largest image expected";
}

void rejectUnknownParameters(const mild::ParameterSource& source) {
  std::vector<std::string> known;
  NodeSettings scratch;
  visitSettings(scratch, [&](const char* name, auto&, const mild::Bounds&, const char*) { known.emplace_back(name); });
  // Read by libraries the node uses, from the same private namespace.
  known.emplace_back("diagnostic_period");
  // Read by the team link itself (TeamLink, docs/multi_robot.md "The team key"): paths, no bound to
  // declare.
  known.emplace_back("team/key_file");
  known.emplace_back("team/station_key_file");
  known.emplace_back("team/roster_dir");
  // Written by the node's own dynamic_reconfigure server (~tuning): the runtime parameters, each
  // with its first '/' as '_'.
  for (std::string name : mild::runtimeParameterNames()) {
    name[name.find('/')] = '_';
    known.push_back("tuning/" + name);
  }
  const auto& sections = mild::detectorParameterNamespaces();
  for (const std::string& name : source.names()) {
    if (std::find(known.begin(), known.end(), name) != known.end()) continue;
    const std::string top = name.substr(0, name.find('/'));
    if (std::find(sections.begin(), sections.end(), top) != sections.end()) continue;  // the detector checks its own
    std::ostringstream names;
    for (size_t i = 0; i < known.size(); ++i) names << (i ? ", " : "") << known[i];
    std::ostringstream detector;
    for (size_t i = 0; i < sections.size(); ++i) detector << (i ? ", " : "") << sections[i] << "/";
    throw InvalidInput("unknown parameter ~" + name + " (the node's own are " + names.str() +
                       "; the detector's are under " + detector.str() + ")");
  }
}

}  // namespace mild_lcd
