// Standalone mild_lcd node: loads mild_lcd/LoopClosureNodelet into its own process, so that
// `rosrun mild_lcd mild_lcd_node` works without a nodelet manager. Remappings and private
// parameters apply as for the nodelet.
//
// SIGINT is handled here rather than by roscpp: the nodelet is unloaded (its queue dropped, its
// map saved, what happened logged) while ROS is still up, and only then is ROS shut down. roscpp's
// own handler shuts ROS down first, after which nothing the nodelet logs is printed.

#include <signal.h>

#include <atomic>
#include <cstring>
#include <iostream>

#include <nodelet/loader.h>
#include <ros/ros.h>

#include "mild_lcd/ros/settings/node_settings.hpp"

namespace {

std::atomic<bool> g_stop{false};

void requestStop(int) { g_stop = true; }

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--help-parameters") == 0) {  // no master needed
      std::cout << mild_lcd::nodeSettingsMarkdown()
                << "\nThe detector's parameters (orb/, index/, ...): config/default.yaml.\n";
      return 0;
    }
  }
  ros::init(argc, argv, "mild_lcd", ros::init_options::NoSigintHandler);
  signal(SIGINT, requestStop);
  signal(SIGTERM, requestStop);
  ros::NodeHandle keep_alive;  // the node stays up while the loader works
  nodelet::Loader loader;
  const nodelet::M_string remappings(ros::names::getRemappings());
  const nodelet::V_string nodelet_argv;
  const std::string name = ros::this_node::getName();
  if (!loader.load(name, "mild_lcd/LoopClosureNodelet", remappings, nodelet_argv)) {
    ROS_FATAL("mild_lcd: the loop-closure nodelet failed to start (see the error above)");
    return 1;
  }
  ros::AsyncSpinner spinner(1);
  spinner.start();
  while (!g_stop && ros::ok()) ros::WallDuration(0.05).sleep();
  spinner.stop();
  loader.unload(name);
  ros::shutdown();
  return 0;
}
