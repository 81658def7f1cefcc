// Standalone mild_lcd node: loads mild_lcd/LoopClosureNodelet into its own process, so that
// `rosrun mild_lcd mild_lcd_node` works without a nodelet manager. Remappings and private
// parameters apply as for the nodelet.
//
// SIGINT is handled here rather than by roscpp: the nodelet is unloaded (its queue dropped, its
// map saved, what happened logged) while ROS is still up, and only then is ROS shut down. roscpp's
// own handler shuts ROS down first, after which nothing the nodelet logs is printed.

#include <signal.h>

#include <atomic>

#include <nodelet/loader.h>
#include <ros/ros.h>

namespace {

std::atomic<bool> g_stop{false};

void requestStop(int) { g_stop = true; }

}  // namespace

int main(int argc, char** argv) {
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
