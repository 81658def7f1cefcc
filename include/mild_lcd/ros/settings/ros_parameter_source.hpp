#pragma once

#include <ros/node_handle.h>

#include "mild_lcd/params/parameter_source.hpp"

namespace mild_lcd {

// The detector's parameters from the ROS parameter server, under a node handle's namespace (the
// nodelet's private one): "orb/num_features" is ~orb/num_features. Integers are accepted where a
// number is expected; anything else of the wrong type is rejected with the parameter's name.
class RosParameterSource : public mild::ParameterSource {
 public:
  explicit RosParameterSource(const ros::NodeHandle& nh) : nh_(nh) {}

  std::optional<double> getDouble(const std::string& name) const override;
  std::optional<int64_t> getInt(const std::string& name) const override;
  std::optional<bool> getBool(const std::string& name) const override;
  std::optional<std::string> getString(const std::string& name) const override;
  std::optional<std::vector<double>> getDoubleList(const std::string& name) const override;
  std::vector<std::string> names() const override;

 private:
  std::optional<XmlRpc::XmlRpcValue> get(const std::string& name) const;
  ros::NodeHandle nh_;
};

}  // namespace mild_lcd
