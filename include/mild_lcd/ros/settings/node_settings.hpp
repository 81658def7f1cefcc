#pragma once

// Settings of the ROS wrapper itself: how keyframes arrive, queueing, the debug image, where maps
// are kept. ROS-free (read through mild::ParameterSource), so tests check them without a master.
// The detector's own parameters are under orb/, index/, ... (config/default.yaml).

#include <string>
#include <vector>

#include "mild_lcd/params/parameter_source.hpp"
#include "mild_lcd/params/parameter_spec.hpp"
#include "mild_lcd/team/place_summary.hpp"

namespace mild {
struct StationSettings;
}  // namespace mild

namespace mild_lcd {

struct NodeSettings {
  bool use_image_input = true;
  bool use_keyframe_input = true;
  std::string image_transport = "raw";
  bool use_camera_info = true;
  bool publish_correspondences = false;
  int queue_size = 100;
  int queue_mb = 256;                 // and at most this many megabytes of messages
  bool extraction_thread = true;      // extract keyframe k+1 while k is processed (KeyframeWorker)
  int debug_image_cache = 1000;       // keyframes kept (half resolution, grey) for debug_image
  int debug_image_cache_mb = 64;      // and at most this many megabytes of them
  int max_image_pixels = 16777216;    // larger images are refused before decoding (4096 x 4096)
  int max_keyframe_features = 10000;  // Keyframe messages with more keypoints are refused
  std::string database_dir;           // the only folder maps are saved to and loaded from
  std::string database_path;          // inside database_dir (a name relative to it, or absolute)
  bool load_on_start = false;
  bool save_on_shutdown = false;
  int autosave_period = 60;         // seconds; with save_on_shutdown, a save this often when changed
  int max_database_mb = 16384;      // larger files are refused unread
  int max_database_files = 100;     // files and folders saves may leave in database_dir
  int max_database_dir_mb = 65536;  // and the megabytes its files may hold before a save is refused
  int max_match_features = 10000;   // per side of a sparse_match request
  std::string robots;               // names of the robots served, space- or comma-separated; "" = one
  // A team across hosts (ros/team/team_link.hpp): this station's name ("" = none) and its bounds.
  std::string team_station;
  int team_summary_bytes = static_cast<int>(mild::kDefaultSummaryBytes);  // descriptor bytes per summary
  int team_backfill_batch = 20;                                           // summaries per request when filling a gap
  double team_peer_timeout = 5.0;         // seconds without a heartbeat: the peer is disconnected
  int team_max_requests_per_second = 20;  // from one peer; more are refused (busy) and counted
  int team_max_pending_pulls = 32;        // per peer: keyframes waiting for their features

  // The robots' names ("" = one robot, topics without a prefix), checked by load().
  std::vector<std::string> robotNames() const;
  // The station protocol's settings (~team/...) for the robots of this node's maps (RobotTeam's
  // names: one robot is named "", and on the wire by the station's name).
  mild::StationSettings stationSettings(std::vector<std::string> robots) const;

  // Reads every setting the source holds, type-checked, and validates them. `default_dir` is where
  // maps go when ~database_dir is not set and ~database_path is relative or empty (the node passes
  // $ROS_HOME/mild_lcd). Throws mild::InvalidInput naming the parameter.
  static NodeSettings load(const mild::ParameterSource& source, const std::string& default_dir);
};

// BRISK and AKAZE describe every keypoint they detect, and AKAZE builds a nonlinear scale space of
// the whole image: their time and memory grow with the pixels and with the keypoints found (noise
// finds the most). A warning for the log when ~max_image_pixels lets such images in (over
// 2048 x 2048 pixels); "" otherwise.
std::string extractionCostWarning(const NodeSettings& settings, const std::string& feature_type);

// One line per setting: name, default and meaning (for --print-config style listings and the
// README's interface table).
struct SettingDoc {
  std::string name;
  std::string default_value;
  std::string range;
  std::string doc;
};
const std::vector<SettingDoc>& nodeSettingDocs();
// The same as a Markdown table (name, default, range, meaning): the README's, printed by
// `mild_lcd_node --help-parameters`.
std::string nodeSettingsMarkdown();

// Throws mild::InvalidInput for the first private parameter that neither the node, the detector nor
// a library the node uses (diagnostic_updater's diagnostic_period) reads: a misspelt name is an
// error, not a silent default.
void rejectUnknownParameters(const mild::ParameterSource& source);

}  // namespace mild_lcd
