#pragma once

// Where parameter values come from, apart from what they mean: the detector's (parameters.hpp) and
// the node's settings (ros/node_settings.hpp) are read through it. Includes nothing of the pipeline.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace mild {

// Where parameter values come from: a YAML file (YamlParameterSource) or the ROS parameter server
// (the nodelet's own source). Names are slash-separated paths such as "orb/num_features".
class ParameterSource {
 public:
  virtual ~ParameterSource() = default;
  // Each returns nullopt when the parameter is absent and throws InvalidInput when it is present
  // with a value of the wrong type.
  virtual std::optional<double> getDouble(const std::string& name) const = 0;
  virtual std::optional<int64_t> getInt(const std::string& name) const = 0;
  virtual std::optional<bool> getBool(const std::string& name) const = 0;
  virtual std::optional<std::string> getString(const std::string& name) const = 0;
  virtual std::optional<std::vector<double>> getDoubleList(const std::string& name) const = 0;
  // Every parameter name the source holds (leaves only).
  virtual std::vector<std::string> names() const = 0;
};

// A YAML file of nested maps (see config/default.yaml). Throws InvalidInput naming the file when it
// cannot be read or parsed.
class YamlParameterSource : public ParameterSource {
 public:
  static YamlParameterSource fromFile(const std::string& path);
  static YamlParameterSource fromString(const std::string& yaml, const std::string& origin = "<string>");

  std::optional<double> getDouble(const std::string& name) const override;
  std::optional<int64_t> getInt(const std::string& name) const override;
  std::optional<bool> getBool(const std::string& name) const override;
  std::optional<std::string> getString(const std::string& name) const override;
  std::optional<std::vector<double>> getDoubleList(const std::string& name) const override;
  std::vector<std::string> names() const override;

 private:
  struct Value {
    bool is_list = false;
    std::vector<std::string> items;
  };
  YamlParameterSource() = default;
  std::optional<std::string> scalar(const std::string& name) const;
  const Value* find(const std::string& name) const;

  std::string origin_;
  std::vector<std::pair<std::string, Value>> values_;
};

}  // namespace mild
