#include "mild_lcd/ros/settings/tuning_config.hpp"

#include <optional>
#include <set>
#include <string>
#include <type_traits>
#include <vector>

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

namespace {

// A dynamic_reconfigure Config as a parameter source, by the detector's names: the request's values
// reach the detector's one typed reader (loadDetectorParams) as the values they are, with no text
// between.
class TuningParameterSource : public mild::ParameterSource {
 public:
  explicit TuningParameterSource(const dynamic_reconfigure::Config& config) : config_(config) {}

  std::optional<double> getDouble(const std::string& name) const override {
    if (const auto* p = find(config_.doubles, name)) return p->value;
    if (const auto* p = find(config_.ints, name)) return static_cast<double>(p->value);
    return std::nullopt;
  }
  std::optional<int64_t> getInt(const std::string& name) const override {
    if (const auto* p = find(config_.ints, name)) return p->value;
    if (find(config_.doubles, name)) throw mild::InvalidInput("parameter " + name + " takes an integer");
    return std::nullopt;
  }
  std::optional<bool> getBool(const std::string& name) const override {
    if (const auto* p = find(config_.bools, name)) return static_cast<bool>(p->value);
    return std::nullopt;
  }
  std::optional<std::string> getString(const std::string& name) const override {
    if (const auto* p = find(config_.strs, name)) return p->value;
    return std::nullopt;
  }
  std::optional<std::vector<double>> getDoubleList(const std::string&) const override { return std::nullopt; }
  std::vector<std::string> names() const override {
    std::vector<std::string> out;
    const auto add = [&](const auto& entries) {
      for (const auto& e : entries) out.push_back(parameterName(e.name));
    };
    add(config_.bools);
    add(config_.ints);
    add(config_.strs);
    add(config_.doubles);
    return out;
  }

 private:
  template <class Entries>
  static const typename Entries::value_type* find(const Entries& entries, const std::string& name) {
    const std::string tuning = tuningName(name);
    for (const auto& e : entries) {
      if (e.name == tuning) return &e;
    }
    return nullptr;
  }

  const dynamic_reconfigure::Config& config_;
};

}  // namespace

mild_lcd::TuningConfig tuningConfigOf(const mild::DetectorParams& params) {
  // The runtime parameters' values as they are, by the type the cfg gives each.
  std::set<std::string> offered;
  for (const auto& d : mild_lcd::TuningConfig::__getParamDescriptions__()) offered.insert(d->name);
  dynamic_reconfigure::Config msg;
  mild::visitParameters(params, [&](const std::string& name, const auto& field, const mild::Bounds&, const char*) {
    using T = std::decay_t<decltype(field)>;
    const std::string tuning = tuningName(name);
    if (!offered.count(tuning)) return;
    if constexpr (std::is_same_v<T, bool>) {
      dynamic_reconfigure::BoolParameter p;
      p.name = tuning;
      p.value = field;
      msg.bools.push_back(p);
    } else if constexpr (std::is_integral_v<T>) {
      dynamic_reconfigure::IntParameter p;
      p.name = tuning;
      p.value = static_cast<int32_t>(field);
      msg.ints.push_back(p);
    } else if constexpr (std::is_floating_point_v<T>) {
      dynamic_reconfigure::DoubleParameter p;
      p.name = tuning;
      p.value = field;
      msg.doubles.push_back(p);
    } else if constexpr (std::is_same_v<T, std::string>) {
      dynamic_reconfigure::StrParameter p;
      p.name = tuning;
      p.value = field;
      msg.strs.push_back(p);
    }
  });
  mild_lcd::TuningConfig config = mild_lcd::TuningConfig::__getDefault__();
  config.__fromMessage__(msg);
  return config;
}

mild::DetectorParams paramsFromTuning(const mild_lcd::TuningConfig& config, const mild::DetectorParams& current) {
  dynamic_reconfigure::Config msg;
  config.__toMessage__(msg);
  return mild::loadDetectorParams(TuningParameterSource(msg), current);
}

}  // namespace mild_lcd
