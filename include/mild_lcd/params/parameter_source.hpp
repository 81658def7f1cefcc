#pragma once

// Where parameter values come from, apart from what they mean: the detector's (detector/detector_parameters.hpp) and
// the node's settings (ros/node_settings.hpp) are read through it. Includes nothing of the pipeline.

#include <cstdint>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "mild_lcd/common/errors.hpp"

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

// Reads `name` from `source` into `field` when the source has it (absent: the field keeps its
// value), by the field's type: bool, double, std::vector<double>, std::string or an integer, whose
// range is checked. Throws InvalidInput for a wrong type or an integer the field cannot hold,
// naming `shown` (default: the name). The one typed read of the detector's parameters and the
// node's settings.
template <class T>
void readParameter(const ParameterSource& source, const std::string& name, T& field, const std::string& shown = "") {
  if constexpr (std::is_same_v<T, bool>) {
    if (auto v = source.getBool(name)) field = *v;
  } else if constexpr (std::is_same_v<T, double>) {
    if (auto v = source.getDouble(name)) field = *v;
  } else if constexpr (std::is_same_v<T, std::vector<double>>) {
    if (auto v = source.getDoubleList(name)) field = *v;
  } else if constexpr (std::is_same_v<T, std::string>) {
    if (auto v = source.getString(name)) field = *v;
  } else {
    static_assert(std::is_integral_v<T>, "a parameter is bool, double, a list of doubles, a string or an integer");
    if (auto v = source.getInt(name)) {
      if (*v < static_cast<int64_t>(std::numeric_limits<T>::min()) ||
          static_cast<uint64_t>(*v) > static_cast<uint64_t>(std::numeric_limits<T>::max()) ||
          (std::is_unsigned_v<T> && *v < 0)) {
        throw InvalidInput("parameter " + (shown.empty() ? name : shown) + " is out of range: " + std::to_string(*v));
      }
      field = static_cast<T>(*v);
    }
  }
}

// A parameter's value as text (logs, --print-config, the generated tables): true/false, strings as
// they are, lists as [a, b], numbers as a stream writes them.
template <class T>
std::string parameterText(const T& v) {
  if constexpr (std::is_same_v<T, std::vector<double>>) {
    std::ostringstream out;
    out << "[";
    for (size_t i = 0; i < v.size(); ++i) out << (i ? ", " : "") << v[i];
    out << "]";
    return out.str();
  } else if constexpr (std::is_same_v<T, bool>) {
    return v ? "true" : "false";
  } else if constexpr (std::is_same_v<T, std::string>) {
    return v;
  } else {
    std::ostringstream out;
    out << v;
    return out.str();
  }
}

}  // namespace mild
