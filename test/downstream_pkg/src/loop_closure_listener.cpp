// Acts on the loops mild_lcd accepts (docs/interface.md, "Consuming LoopClosure"). Subscribes to
// `loop_closure`: remap it to the detector's (e.g. `loop_closure:=/robot/loop_closure`).
#include <mild_lcd/LoopClosure.h>
#include <ros/ros.h>

void onLoopClosure(const mild_lcd::LoopClosure::ConstPtr& msg) {
  for (const mild_lcd::LoopCandidate& c : msg->candidates) {
    if (!c.accepted) continue;  // verified, probability >= the decision (0.909): act on it
    ROS_INFO_STREAM("keyframe " << msg->query_id << " closes a loop with " << c.id << " (p=" << c.probability << ", "
                                << c.inliers << " inliers)");
    if (c.has_relative_pose) {  // the candidate camera in the query camera's optical frame
      const geometry_msgs::Vector3& t = c.relative_translation;
      ROS_INFO_STREAM("  translation " << (c.metric_translation ? "in metres " : "direction ") << t.x << " " << t.y
                                       << " " << t.z);
    }
  }
}

int main(int argc, char** argv) {
  ros::init(argc, argv, "loop_closure_listener");
  ros::NodeHandle nh;
  const ros::Subscriber sub = nh.subscribe("loop_closure", 100, onLoopClosure);
  ros::spin();
  return 0;
}
