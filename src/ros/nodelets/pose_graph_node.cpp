// Standalone node of the example back-end: loads mild_lcd/PoseGraphNodelet into its own process
// (`rosrun mild_lcd mild_lcd_pose_graph_node`). Remappings and private parameters apply as for the
// nodelet; --help-parameters prints its parameters without a master.

#include <cstring>
#include <iostream>

#include <nodelet/loader.h>
#include <ros/ros.h>

#include "mild_lcd/ros/settings/pose_graph_settings.hpp"

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help-parameters") == 0) {
      std::cout << mild_lcd::poseGraphSettingsMarkdown();
      return 0;
    }
  }
  ros::init(argc, argv, "mild_lcd_pose_graph");
  nodelet::Loader loader;
  const nodelet::M_string remappings(ros::names::getRemappings());
  const nodelet::V_string nodelet_argv;
  if (!loader.load(ros::this_node::getName(), "mild_lcd/PoseGraphNodelet", remappings, nodelet_argv)) {
    ROS_FATAL("mild_lcd: the pose-graph nodelet failed to start (see the error above)");
    return 1;
  }
  ros::spin();
  return 0;
}
