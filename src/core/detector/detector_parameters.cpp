#include "mild_lcd/detector/detector_parameters.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <type_traits>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/index/substring_layout.hpp"

namespace mild {
namespace {

template <class T>
std::string toText(const T& v) {
  if constexpr (std::is_same_v<T, SearchMode>) {
    return searchModeName(v);
  } else {
    return parameterText(v);
  }
}

bool inNamespaces(const std::string& name) {
  for (const std::string& ns : detectorParameterNamespaces()) {
    if (name.compare(0, ns.size() + 1, ns + "/") == 0) return true;
  }
  return false;
}

}  // namespace

DatabaseParams DetectorParams::databaseParams() const {
  DatabaseParams p = database;
  p.descriptor_bytes = features.descriptorBytes();
  return p;
}

void DetectorParams::validate() const {
  features.validate();
  const DatabaseParams db = databaseParams();
  db.validate();
  // The layouts the width implies: substrings of at most 64 bits (index), 20 (sparse match).
  const int bits = db.descriptor_bytes * 8;
  const int fewest = std::max(SubstringLayout::kMinSubstrings,
                              SubstringLayout::substringsFor(bits, SubstringLayout::kMaxSubstringBits));
  if (db.index.tablesFor(bits) < fewest) {
    throw InvalidInput("index/num_tables must be 0 (automatic) or at least " + std::to_string(fewest) + " for " +
                       std::to_string(bits) + "-bit descriptors (substrings of at most 64 bits), got " +
                       std::to_string(db.index.num_tables));
  }
  filter.validate();
  candidates.validate();
  if (verification.enabled) {
    verification.validate();
    verification.matching.validateFor(bits);
  }
  scoring.validate();
  if (scoring.enabled && verification.enabled && scoring.filter_type != filter.type) {
    throw InvalidInput("scoring/weights were fitted with filter/type " + scoring.filter_type +
                       " but this detector runs " + filter.type +
                       ": its probability would be miscalibrated. Refit them on runs of " + filter.type +
                       " (scripts/fit_scoring.py) and set scoring/filter_type, or set scoring/enabled false");
  }
}

const std::vector<ParameterSection>& parameterSections() {
  static const std::vector<ParameterSection> sections = [] {
    std::vector<ParameterSection> out;
    // The extension points' sections carry their own doc (kDoc); the stages' are here.
    const auto add = [&](const auto& section) { out.push_back({section.kSection, section.kDoc}); };
    const auto stage = [&](const auto& section, const char* doc) { out.push_back({section.kSection, doc}); };
    const DetectorParams p;
    add(p.features);
    forEachSection(p.features.extractors, add);
    stage(p.database.index, "Multi-index hashing of the stored descriptors (seed paper III.B).");
    stage(p.database.similarity,
          "Image similarity by voting (seed paper III.A, III.C-E). Distances are given per 256 bits.");
    add(p.filter);
    forEachSection(p.filter.filters, add);
    stage(p.candidates, "Which stored keyframes may be candidates, and how many are reported.");
    stage(p.verification, "Geometric verification: sparse match of query and candidate, then a two-view model.");
    stage(p.scoring, "The calibrated loop probability every candidate is published with.");
    return out;
  }();
  return sections;
}

std::string legacyParameterName(const std::string& name) {
  const size_t slash = name.find('/');
  if (slash == std::string::npos) return "";
  const auto& filters = temporalFilterTypes();
  if (std::find(filters.begin(), filters.end(), name.substr(0, slash)) == filters.end()) return "";
  return std::string(FilterParams::kSection) + name.substr(slash);
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
  // Earlier names first, so that a file holding both lets the current name decide.
  const auto read = [&](const std::string& name, auto& field) {
    using T = std::decay_t<decltype(field)>;
    if constexpr (std::is_same_v<T, SearchMode>) {
      if (auto v = source.getString(name)) {
        if (*v == "index")
          field = SearchMode::kIndex;
        else if (*v == "exact")
          field = SearchMode::kExact;
        else
          throw InvalidInput("parameter " + name + " must be 'index' or 'exact', got '" + *v + "'");
      }
    } else {
      readParameter(source, name, field);
    }
  };
  visitParameters(p, [&](const std::string& name, auto& field, const Bounds&, const char*) {
    const std::string legacy = legacyParameterName(name);
    if (!legacy.empty()) {
      known.push_back(legacy);
      read(legacy, field);
    }
    known.push_back(name);
    read(name, field);
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

void copyRuntimeParameters(const DetectorParams& from, DetectorParams& into) {
  // Both walks visit the same fields in the same order with the same types (one template, const and
  // not), so the i-th field of `from` is the i-th of `into`.
  std::vector<const void*> source;
  visitParameters(from,
                  [&](const std::string&, const auto& field, const Bounds&, const char*) { source.push_back(&field); });
  size_t i = 0;
  visitParameters(into, [&](const std::string&, auto& field, const Bounds& bounds, const char*) {
    using T = std::decay_t<decltype(field)>;
    if (bounds.isRuntime()) field = *static_cast<const T*>(source[i]);
    ++i;
  });
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
         "# The filters' sections are named after them; their names of earlier versions, filter/<name>,\n"
         "# still set <name> in every filter section that has it.\n"
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

}  // namespace mild
