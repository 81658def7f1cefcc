#pragma once

// Settings of the example back-end's nodelet (mild_lcd/PoseGraphNodelet): where keyframe poses and
// the camera's mounting come from, which loops it uses, what it publishes; the optimiser's own
// parameters are graph/... (mild::backend::PoseGraphParams). Declared once, in
// src/ros/settings/pose_graph_settings.cpp; ROS-free (read through mild::ParameterSource).

#include <string>

#include "mild_lcd/backend/pose_graph.hpp"
#include "mild_lcd/params/parameter_source.hpp"

namespace mild_lcd {

struct PoseGraphSettings {
  bool use_odometry_topic = true;
  std::string map_frame = "map";
  std::string odom_frame = "odom";
  std::string base_frame = "base_link";
  std::string camera_frame;
  bool use_all_verified = false;
  double odometry_wait = 2.0;
  double max_future_stamp = 1.0;
  int max_waiting = 1000;
  std::string robot;
  double max_odometry_step = 50.0;
  double max_extrinsics_distance = 10.0;
  bool publish_tf = true;
  double tf_rate = 20.0;
  double publish_rate = 2.0;
  mild::backend::PoseGraphParams graph;

  // Reads every setting the source holds, type-checked, rejects unknown names and validates.
  // Throws mild::InvalidInput naming the parameter.
  static PoseGraphSettings load(const mild::ParameterSource& source);
};

// The settings and graph/ parameters as a Markdown table (`mild_lcd_pose_graph_node --help-parameters`).
std::string poseGraphSettingsMarkdown();

}  // namespace mild_lcd
