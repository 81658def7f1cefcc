#pragma once

// An Eigen rotation as a geometry_msgs quaternion, for the tools that write ROS messages
// (mild_make_bag, mild_bench_backend). tf2_eigen has the same conversion but is not among the
// packages this one depends on.

#include <geometry_msgs/Quaternion.h>
#include <Eigen/Geometry>

namespace mild::tools {

inline geometry_msgs::Quaternion quaternion(const Eigen::Quaterniond& q) {
  geometry_msgs::Quaternion m;
  m.w = q.w();
  m.x = q.x();
  m.y = q.y();
  m.z = q.z();
  return m;
}

}  // namespace mild::tools
