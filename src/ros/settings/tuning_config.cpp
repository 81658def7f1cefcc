#include "mild_lcd/ros/settings/tuning_config.hpp"

#include <cstdio>
#include <map>
#include <sstream>

#include <dynamic_reconfigure/Config.h>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/ros/settings/tuning_cfg.hpp"

namespace mild_lcd {

std::string unreadTuningEntries(const dynamic_reconfigure::Config& request) {
  std::string problems;
  const auto check = [&](const std::string& name, const char* type) {
    std::string expected;
    for (const auto& d : mild_lcd::TuningConfig::__getParamDescriptions__()) {
      if (d->name == name) expected = d->type;
    }
    std::string problem;
    if (expected.empty()) {
      problem = "'" + name + "' is not a tuning parameter";
    } else if (expected != type) {
      problem = "'" + name + "' takes " + expected + " values, not " + type;
    }
    if (!problem.empty()) problems += (problems.empty() ? "" : "; ") + problem;
  };
  for (const auto& p : request.bools) check(p.name, "bool");
  for (const auto& p : request.ints) check(p.name, "int");
  for (const auto& p : request.strs) check(p.name, "str");
  for (const auto& p : request.doubles) check(p.name, "double");
  return problems;
}

mild_lcd::TuningConfig tuningConfigOf(const mild::DetectorParams& params) {
  std::map<std::string, std::string> values;
  for (const auto& [name, value] : mild::describeParameters(params)) values[tuningName(name)] = value;
  dynamic_reconfigure::Config msg;
  for (const auto& d : mild_lcd::TuningConfig::__getParamDescriptions__()) {
    const std::string& value = values.at(d->name);
    if (d->type == "int") {
      dynamic_reconfigure::IntParameter p;
      p.name = d->name;
      p.value = std::stoi(value);
      msg.ints.push_back(p);
    } else {
      dynamic_reconfigure::DoubleParameter p;
      p.name = d->name;
      p.value = std::stod(value);
      msg.doubles.push_back(p);
    }
  }
  mild_lcd::TuningConfig config = mild_lcd::TuningConfig::__getDefault__();
  config.__fromMessage__(msg);
  return config;
}

mild::DetectorParams paramsFromTuning(const mild_lcd::TuningConfig& config, const mild::DetectorParams& current) {
  dynamic_reconfigure::Config msg;
  config.__toMessage__(msg);
  // Through the registry, as YAML: one namespace per block.
  std::map<std::string, std::ostringstream> blocks;
  const auto add = [&](const std::string& tuning_name, const std::string& value) {
    const std::string name = parameterName(tuning_name);
    const size_t slash = name.find('/');
    blocks[name.substr(0, slash)] << "  " << name.substr(slash + 1) << ": " << value << "\n";
  };
  for (const auto& p : msg.ints) add(p.name, std::to_string(p.value));
  for (const auto& p : msg.doubles) {
    char text[32];
    std::snprintf(text, sizeof(text), "%.17g", p.value);
    add(p.name, text);
  }
  std::string yaml;
  for (const auto& [ns, lines] : blocks) yaml += ns + ":\n" + lines.str();
  return mild::loadDetectorParams(mild::YamlParameterSource::fromString(yaml, "dynamic_reconfigure"), current);
}

}  // namespace mild_lcd
