// Standalone mild_lcd node: loads mild_lcd/LoopClosureNodelet into its own process, so that
// `rosrun mild_lcd mild_lcd_node` works without a nodelet manager. Remappings and private
// parameters apply as for the nodelet.

#include <nodelet/loader.h>
#include <ros/ros.h>

int main(int argc, char** argv) {
  ros::init(argc, argv, "mild_lcd");
  nodelet::Loader loader;
  const nodelet::M_string remappings(ros::names::getRemappings());
  const nodelet::V_string nodelet_argv;
  if (!loader.load(ros::this_node::getName(), "mild_lcd/LoopClosureNodelet", remappings, nodelet_argv)) {
    ROS_FATAL("mild_lcd: the loop-closure nodelet failed to start (see the error above)");
    return 1;
  }
  ros::spin();
  return 0;
}
