#include "mild_lcd/ros/pose_graph_settings.hpp"

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
  visit("odometry_wait", s.odometry_wait, Bounds::above(0),
        "seconds a keyframe waits for odometry (or tf) at its stamp before it is dropped with a warning");
  visit("publish_tf", s.publish_tf, Bounds::any(), "broadcast map_frame -> odom_frame");
  visit("tf_rate", s.tf_rate, Bounds::above(0),
        "rate of that broadcast, and of retrying the keyframes that wait for their pose, Hz");
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
