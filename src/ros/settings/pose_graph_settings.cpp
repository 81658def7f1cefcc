#include "mild_lcd/ros/settings/pose_graph_settings.hpp"

#include <algorithm>
#include <limits>
#include <sstream>
#include <type_traits>

#include "mild_lcd/common/errors.hpp"

namespace mild_lcd {
namespace {

using mild::Bounds;
using mild::InvalidInput;

// The single declaration of the nodelet's own settings: name, field, bounds, meaning.
template <class Settings, class Visit>
void visitSettings(Settings& s, Visit&& visit) {
  visit("use_odometry_topic", s.use_odometry_topic, Bounds::any(),
        "keyframe poses from `odom` (nav_msgs/Odometry, interpolated at the keyframe's stamp); false: from tf "
        "odom_frame -> base_frame at the stamp");
  visit("map_frame", s.map_frame, Bounds::any(), "frame of the corrected trajectory and parent of the map -> odom tf");
  visit("odom_frame", s.odom_frame, Bounds::any(), "the odometry's frame (REP 105)");
  visit("base_frame", s.base_frame, Bounds::any(), "the robot's base frame (x forward, z up)");
  visit("camera_frame", s.camera_frame, Bounds::any(),
        "the keyframes' camera (optical) frame for the extrinsics, from tf base_frame -> camera_frame; empty: "
        "LoopClosure's header.frame_id");
  visit("use_all_verified", s.use_all_verified, Bounds::any(),
        "loop edges from every verified candidate with a relative pose; false: the accepted ones only");
  visit("odometry_wait", s.odometry_wait, Bounds::aboveUpTo(0, 3600),
        "seconds a keyframe waits for odometry (or tf) at its stamp before it is dropped (counted in the "
        "diagnostics, with a warning)");
  visit("max_future_stamp", s.max_future_stamp, Bounds::in(0, 3600),
        "a keyframe stamped more than this many seconds ahead of the clock is dropped at once (counted): it would "
        "hold back every keyframe after it");
  visit("max_waiting", s.max_waiting, Bounds::in(1, 1000000),
        "keyframes waiting for their pose, at most; beyond, the oldest is dropped (counted)");
  visit("robot", s.robot, Bounds::any(),
        "the robot (LoopClosure.query_robot) whose keyframes form the trajectory; empty: the first one seen. Other "
        "robots' keyframes, and loops to other robots' keyframes, are counted and skipped");
  visit("max_odometry_step", s.max_odometry_step, Bounds::aboveUpTo(0, 1e6),
        "metres the odometry may move between consecutive keyframes: a keyframe beyond is dropped as a spike "
        "(counted); three in a row start a new odometry chain (the odometry restarted)");
  visit("max_extrinsics_distance", s.max_extrinsics_distance, Bounds::aboveUpTo(0, 1e6),
        "metres the camera may sit from the base: a tf base_frame -> camera farther (or not finite, or not a "
        "rotation) is refused (counted) and a forward-looking camera at the base's origin is used");
  visit("publish_tf", s.publish_tf, Bounds::any(), "broadcast map_frame -> odom_frame");
  visit("tf_rate", s.tf_rate, Bounds::aboveUpTo(0, 1000),
        "rate of that broadcast, and of retrying the keyframes that wait for their pose, Hz");
  visit("publish_rate", s.publish_rate, Bounds::aboveUpTo(0, 1000),
        "the trajectory, odometry path and loop markers are published at most this often, Hz (each holds every "
        "keyframe: publishing them per keyframe would cost O(n) each); always once after the last change");
}

template <class T>
std::string text(const T& v) {
  if constexpr (std::is_same_v<T, bool>) {
    return v ? "true" : "false";
  } else if constexpr (std::is_same_v<T, std::string>) {
    return v.empty() ? "\"\"" : v;
  } else {
    std::ostringstream out;
    out << v;
    return out.str();
  }
}

}  // namespace

PoseGraphSettings PoseGraphSettings::load(const mild::ParameterSource& source) {
  PoseGraphSettings s;
  std::vector<std::string> known;
  visitSettings(s, [&](const char* name, auto& field, const Bounds&, const char*) {
    known.emplace_back(name);
    using T = std::decay_t<decltype(field)>;
    if constexpr (std::is_same_v<T, bool>) {
      if (auto v = source.getBool(name)) field = *v;
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (auto v = source.getString(name)) field = *v;
    } else if constexpr (std::is_same_v<T, int>) {
      if (auto v = source.getInt(name)) {
        if (*v < 0 || *v > std::numeric_limits<int>::max())
          throw InvalidInput("parameter ~" + std::string(name) + " is out of range");
        field = static_cast<int>(*v);
      }
    } else {
      if (auto v = source.getDouble(name)) field = *v;
    }
  });
  for (const std::string& name : source.names()) {
    if (name.compare(0, 6, "graph/") == 0) continue;  // loadPoseGraphParams checks its own
    if (std::find(known.begin(), known.end(), name) != known.end()) continue;
    std::string names;
    for (const std::string& k : known) names += (names.empty() ? "" : ", ") + k;
    throw InvalidInput("unknown parameter ~" + name + " (the pose graph node's are " + names + " and graph/...)");
  }
  visitSettings(s, [](const char* name, const auto& field, const Bounds& bounds, const char*) {
    bounds.check(std::string("parameter ~") + name, field);
  });
  for (const std::string* frame : {&s.map_frame, &s.odom_frame, &s.base_frame}) {
    if (frame->empty()) throw InvalidInput("parameters ~map_frame, ~odom_frame and ~base_frame must name frames");
  }
  s.graph = mild::backend::loadPoseGraphParams(source);
  return s;
}

std::string poseGraphSettingsMarkdown() {
  std::ostringstream out;
  out << "| parameter | default | range | meaning |\n|---|---|---|---|\n";
  PoseGraphSettings defaults;
  visitSettings(defaults, [&](const char* name, const auto& field, const Bounds& bounds, const char* doc) {
    out << "| `~" << name << "` | `" << text(field) << "` | " << bounds.text() << " | " << doc << " |\n";
  });
  out << mild::backend::poseGraphParameterMarkdown("~graph/");
  return out.str();
}

}  // namespace mild_lcd
