#include "mild_lcd/params/parameters.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <type_traits>

#include <yaml-cpp/yaml.h>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

template <class T>
std::string toText(const T& v) {
  if constexpr (std::is_same_v<T, std::vector<double>>) {
    std::ostringstream out;
    out << "[";
    for (size_t i = 0; i < v.size(); ++i) out << (i ? ", " : "") << v[i];
    out << "]";
    return out.str();
  } else if constexpr (std::is_same_v<T, bool>) {
    return v ? "true" : "false";
  } else if constexpr (std::is_same_v<T, SearchMode>) {
    return searchModeName(v);
  } else if constexpr (std::is_same_v<T, std::string>) {
    return v;
  } else {
    std::ostringstream out;
    out << v;
    return out.str();
  }
}

bool inNamespaces(const std::string& name) {
  for (const std::string& ns : detectorParameterNamespaces()) {
    if (name.compare(0, ns.size() + 1, ns + "/") == 0) return true;
  }
  return false;
}

}  // namespace

const std::vector<std::string>& detectorParameterNamespaces() {
  static const std::vector<std::string> namespaces = {"orb",      "index",        "similarity", "filter",
                                                      "detector", "verification", "scoring"};
  return namespaces;
}

DetectorParams loadDetectorParams(const ParameterSource& source, const DetectorParams& defaults) {
  DetectorParams p = defaults;
  std::vector<std::string> known;
  visitParameters(p, [&](const std::string& name, auto& field) {
    using T = std::decay_t<decltype(field)>;
    known.push_back(name);
    if constexpr (std::is_same_v<T, bool>) {
      if (auto v = source.getBool(name)) field = *v;
    } else if constexpr (std::is_same_v<T, double>) {
      if (auto v = source.getDouble(name)) field = *v;
    } else if constexpr (std::is_same_v<T, std::vector<double>>) {
      if (auto v = source.getDoubleList(name)) field = *v;
    } else if constexpr (std::is_same_v<T, std::string>) {
      if (auto v = source.getString(name)) field = *v;
    } else if constexpr (std::is_same_v<T, SearchMode>) {
      if (auto v = source.getString(name)) {
        if (*v == "index")
          field = SearchMode::kIndex;
        else if (*v == "exact")
          field = SearchMode::kExact;
        else
          throw InvalidInput("parameter " + name + " must be 'index' or 'exact', got '" + *v + "'");
      }
    } else {
      static_assert(std::is_integral_v<T>);
      if (auto v = source.getInt(name)) {
        if (*v < static_cast<int64_t>(std::numeric_limits<T>::min()) ||
            static_cast<uint64_t>(*v) > static_cast<uint64_t>(std::numeric_limits<T>::max()) ||
            (std::is_unsigned_v<T> && *v < 0)) {
          throw InvalidInput("parameter " + name + " is out of range: " + std::to_string(*v));
        }
        field = static_cast<T>(*v);
      }
    }
  });
  const auto& namespaces = detectorParameterNamespaces();
  for (const std::string& name : source.names()) {
    if (std::find(namespaces.begin(), namespaces.end(), name) != namespaces.end()) {
      throw InvalidInput("'" + name + "' must be a section of named parameters (see config/default.yaml)");
    }
    if (inNamespaces(name) && std::find(known.begin(), known.end(), name) == known.end()) {
      throw InvalidInput("unknown parameter '" + name + "' (check the spelling against config/default.yaml)");
    }
  }
  p.validate();
  return p;
}

const std::vector<std::string>& runtimeParameterNames() {
  static const std::vector<std::string> names = {
      "detector/exclusion_frames",   "detector/exclusion_seconds",    "detector/max_candidates",
      "detector/suppression_radius", "detector/min_probability",      "scoring/decision_probability",
      "verification/min_inliers",    "verification/ransac_threshold", "verification/ratio",
      "verification/pnp_threshold",
  };
  return names;
}

std::vector<std::pair<std::string, std::string>> describeParameters(const DetectorParams& params) {
  DetectorParams p = params;
  std::vector<std::pair<std::string, std::string>> out;
  visitParameters(p, [&](const std::string& name, auto& field) { out.emplace_back(name, toText(field)); });
  return out;
}

// --- YAML ------------------------------------------------------------------------------------

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

std::optional<double> parseDouble(const std::string& text) {
  try {
    size_t used = 0;
    const double v = std::stod(text, &used);
    if (used == text.size()) return v;
  } catch (const std::exception&) {
  }
  return std::nullopt;
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
