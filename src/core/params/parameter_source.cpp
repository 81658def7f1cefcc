#include "mild_lcd/params/parameter_source.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "mild_lcd/common/errors.hpp"

namespace mild {

namespace {

template <class Value>
void flatten(const YAML::Node& node, const std::string& prefix, std::vector<std::pair<std::string, Value>>& out,
             const std::string& origin) {
  if (node.IsMap()) {
    for (const auto& kv : node) {
      const std::string key = kv.first.as<std::string>();
      flatten(kv.second, prefix.empty() ? key : prefix + "/" + key, out, origin);
    }
  } else if (node.IsScalar()) {
    out.emplace_back(prefix, Value{false, {node.Scalar()}});
  } else if (node.IsSequence()) {
    Value list{true, {}};
    for (const auto& item : node) {
      if (!item.IsScalar()) throw InvalidInput(origin + ": parameter '" + prefix + "' must be a list of numbers");
      list.items.push_back(item.Scalar());
    }
    out.emplace_back(prefix, list);
  }
  // a null node (an empty section such as "filter:") sets nothing
}

// A number in full, as std::stod reads it, except that values below the smallest normal double
// (the generated cfg's bound just above 0 is 4.9e-324) are numbers too: stod refuses their ERANGE.
std::optional<double> parseDouble(const std::string& text) {
  const char* begin = text.c_str();
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(begin, &end);
  if (end == begin || end != begin + text.size()) return std::nullopt;
  if (errno == ERANGE && std::isinf(v)) return std::nullopt;  // overflow
  return v;
}

}  // namespace

YamlParameterSource YamlParameterSource::fromString(const std::string& yaml, const std::string& origin) {
  YamlParameterSource source;
  source.origin_ = origin;
  try {
    const YAML::Node root = YAML::Load(yaml);
    if (!root.IsNull() && !root.IsMap()) throw InvalidInput(origin + ": expected a map of parameters at the top level");
    flatten(root, "", source.values_, origin);
  } catch (const YAML::Exception& e) {
    throw InvalidInput(origin + ": not valid YAML: " + e.what());
  }
  return source;
}

YamlParameterSource YamlParameterSource::fromFile(const std::string& path) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    throw InvalidInput(path + ": not a parameter file (missing, or not a regular file)");
  }
  std::ifstream in(path);
  if (!in) throw InvalidInput(path + ": cannot read the file");
  std::ostringstream text;
  text << in.rdbuf();
  return fromString(text.str(), path);
}

const YamlParameterSource::Value* YamlParameterSource::find(const std::string& name) const {
  for (const auto& [key, value] : values_) {
    if (key == name) return &value;
  }
  return nullptr;
}

std::optional<std::string> YamlParameterSource::scalar(const std::string& name) const {
  const Value* v = find(name);
  if (v == nullptr) return std::nullopt;
  if (v->is_list) throw InvalidInput(origin_ + ": parameter " + name + " must be a single value, not a list");
  return v->items.front();
}

std::optional<double> YamlParameterSource::getDouble(const std::string& name) const {
  auto text = scalar(name);
  if (!text) return std::nullopt;
  if (auto v = parseDouble(*text)) return v;
  throw InvalidInput(origin_ + ": parameter " + name + " must be a number, got '" + *text + "'");
}

std::optional<std::vector<double>> YamlParameterSource::getDoubleList(const std::string& name) const {
  const Value* v = find(name);
  if (v == nullptr) return std::nullopt;
  if (!v->is_list)
    throw InvalidInput(origin_ + ": parameter " + name + " must be a list of numbers, such as [0.3, 1.0]");
  std::vector<double> out;
  for (const std::string& item : v->items) {
    auto d = parseDouble(item);
    if (!d) throw InvalidInput(origin_ + ": parameter " + name + " must be a list of numbers, got item '" + item + "'");
    out.push_back(*d);
  }
  return out;
}

std::optional<int64_t> YamlParameterSource::getInt(const std::string& name) const {
  auto text = scalar(name);
  if (!text) return std::nullopt;
  try {
    size_t used = 0;
    const long long v = std::stoll(*text, &used);
    if (used == text->size()) return v;
  } catch (const std::exception&) {
  }
  throw InvalidInput(origin_ + ": parameter " + name + " must be an integer, got '" + *text + "'");
}

std::optional<bool> YamlParameterSource::getBool(const std::string& name) const {
  auto text = scalar(name);
  if (!text) return std::nullopt;
  if (*text == "true" || *text == "True" || *text == "TRUE") return true;
  if (*text == "false" || *text == "False" || *text == "FALSE") return false;
  throw InvalidInput(origin_ + ": parameter " + name + " must be true or false, got '" + *text + "'");
}

std::optional<std::string> YamlParameterSource::getString(const std::string& name) const { return scalar(name); }

std::vector<std::string> YamlParameterSource::names() const {
  std::vector<std::string> out;
  for (const auto& kv : values_) out.push_back(kv.first);
  return out;
}

}  // namespace mild
