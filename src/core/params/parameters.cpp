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

const std::vector<ParameterSection>& parameterSections() {
  static const std::vector<ParameterSection> sections = {
      {"features", "Where a keyframe's features come from when the node is given images."},
      {"orb", "ORB (OpenCV), features/type orb: 256-bit descriptors."},
      {"brisk", "BRISK (OpenCV), features/type brisk: 512-bit descriptors, as OKVIS and maplab use."},
      {"akaze", "AKAZE with its M-LDB descriptor (OpenCV), features/type akaze: 486 bits in 61 bytes."},
      {"index", "Multi-index hashing of the stored descriptors (seed paper III.B)."},
      {"similarity", "Image similarity by voting (seed paper III.A, III.C-E). Distances are given per 256 bits."},
      {"filter", "The temporal filter that turns similarity into a loop probability."},
      {"detector", "Which stored keyframes may be candidates, and how many are reported."},
      {"verification", "Geometric verification: sparse match of query and candidate, then a two-view model."},
      {"scoring", "The calibrated loop probability every candidate is published with."},
  };
  return sections;
}

const std::vector<std::string>& detectorParameterNamespaces() {
  static const std::vector<std::string> namespaces = [] {
    std::vector<std::string> out;
    for (const ParameterSection& s : parameterSections()) out.push_back(s.name);
    return out;
  }();
  return namespaces;
}

DetectorParams loadDetectorParams(const ParameterSource& source, const DetectorParams& defaults) {
  DetectorParams p = defaults;
  std::vector<std::string> known;
  visitParameters(p, [&](const std::string& name, auto& field, const Bounds&, const char*) {
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
  static const std::vector<std::string> names = [] {
    std::vector<std::string> out;
    const DetectorParams defaults;
    visitParameters(defaults, [&](const std::string& name, const auto&, const Bounds& bounds, const char*) {
      if (bounds.isRuntime()) out.push_back(name);
    });
    return out;
  }();
  return names;
}

std::vector<std::pair<std::string, std::string>> describeParameters(const DetectorParams& p,
                                                                    const std::string& section) {
  std::vector<std::pair<std::string, std::string>> out;
  const std::string prefix = section + "/";
  visitParameters(p, [&](const std::string& name, const auto& field, const Bounds&, const char*) {
    if (section.empty() || name.compare(0, prefix.size(), prefix) == 0) out.emplace_back(name, toText(field));
  });
  return out;
}

namespace {

// Words of `text` in lines of at most `width` characters, each starting with `indent`.
std::string wrapped(const std::string& text, const std::string& indent, size_t width = 100) {
  std::istringstream words(text);
  std::string word, line, out;
  while (words >> word) {
    if (!line.empty() && indent.size() + line.size() + 1 + word.size() > width) {
      out += indent + line + "\n";
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
  }
  if (!line.empty()) out += indent + line + "\n";
  return out;
}

template <class T>
std::string yamlValue(const T& v) {
  if constexpr (std::is_same_v<T, double>) {
    std::string text = toText(v);
    // A whole number stays a YAML float, so that the file reads back as the type it documents.
    if (text.find_first_of(".e") == std::string::npos && text.find("inf") == std::string::npos) text += ".0";
    return text;
  } else {
    return toText(v);
  }
}

}  // namespace

std::string parameterYaml(const DetectorParams& params) {
  std::ostringstream out;
  out << "# mild_lcd detector parameters. Generated from their declarations in the code (with the defaults:\n"
         "# config/default.yaml, which a test keeps equal to `mild_offline --print-config`): edit the code.\n"
         "# The same names work in three places:\n"
         "#   mild_offline --config FILE.yaml       (this layout)\n"
         "#   the nodelet's private namespace       (<rosparam file=\"...\" command=\"load\"/>, e.g. "
         "~orb/num_features)\n"
         "#   your own YAML, listing only what you change.\n"
         "# Unknown names in these sections, wrong types and values out of range stop the node at start-up\n"
         "# with a message naming the parameter. [runtime] marks what dynamic_reconfigure may change while\n"
         "# the node runs; everything else is read at start-up only. Figures quoted were measured on\n"
         "# ../shared/bench; the filter, near-past and scoring values were chosen by leave-one-kind-out\n"
         "# cross-validation (docs/accuracy.md), one configuration for every scene.\n";
  std::string section;
  visitParameters(params, [&](const std::string& name, const auto& field, const Bounds& bounds, const char* doc) {
    const size_t slash = name.find('/');
    const std::string here = name.substr(0, slash);
    if (here != section) {
      section = here;
      out << "\n" << section << ":\n";
      for (const ParameterSection& s : parameterSections()) {
        if (s.name == section) out << wrapped(s.doc, "  ## ");
      }
    }
    out << wrapped(doc, "  # ");
    const std::string range = bounds.text();
    if (!range.empty() || bounds.isRuntime()) {
      out << "  #" << (range.empty() ? "" : " Range: " + range + ".") << (bounds.isRuntime() ? " [runtime]" : "")
          << "\n";
    }
    out << "  " << name.substr(slash + 1) << ": " << yamlValue(field) << "\n";
  });
  return out.str();
}

std::string parameterMarkdown() {
  std::ostringstream out;
  out << "| parameter | default | range | live | meaning |\n|---|---|---|---|---|\n";
  const DetectorParams defaults;
  visitParameters(defaults, [&](const std::string& name, const auto& field, const Bounds& bounds, const char* doc) {
    std::string meaning = doc;
    for (char& c : meaning) {
      if (c == '|') c = '/';
    }
    out << "| `" << name << "` | `" << yamlValue(field) << "` | " << bounds.text() << " | "
        << (bounds.isRuntime() ? "yes" : "") << " | " << meaning << " |\n";
  });
  return out.str();
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
