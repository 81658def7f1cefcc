#include "mild_lcd/ros/settings/tuning_cfg.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <type_traits>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"

namespace mild_lcd {
namespace {

// A Python float literal that reads back as exactly `v` (never an int: "1" would make it one).
std::string pythonFloat(double v) {
  char text[40];
  std::snprintf(text, sizeof(text), "%.17g", v);
  std::string s = text;
  if (s.find_first_of(".e") == std::string::npos) s += ".0";
  return s;
}

// A Python string literal of a parameter's doc: ParameterGenerator copies it into C++ and Python
// sources, so quotes and backslashes are replaced rather than escaped twice over.
std::string pythonText(std::string doc) {
  for (char& c : doc) {
    if (c == '"' || c == '\\') c = '\'';
    if (c == '\n') c = ' ';
  }
  return "\"" + doc + "\"";
}

// The closed range dynamic_reconfigure clamps to: an open bound becomes the nearest value inside
// it, and an unbounded double the largest finite one (the detector takes finite numbers only), so
// that every value it lets through the detector accepts. "" = dynamic_reconfigure's int range.
std::string lowest(const mild::Bounds& b, bool integral) {
  if (b.allowsZero() && b.lower() >= 0.0) return integral ? "0" : "0.0";
  if (std::isinf(b.lower())) return integral ? "" : pythonFloat(std::numeric_limits<double>::lowest());
  if (integral)
    return std::to_string(static_cast<long long>(b.lowerOpen() ? std::floor(b.lower()) + 1 : std::ceil(b.lower())));
  return pythonFloat(b.lowerOpen() ? std::nextafter(b.lower(), std::numeric_limits<double>::infinity()) : b.lower());
}

std::string highest(const mild::Bounds& b, bool integral) {
  if (std::isinf(b.upper())) return integral ? "" : pythonFloat(std::numeric_limits<double>::max());
  if (integral)
    return std::to_string(static_cast<long long>(b.upperOpen() ? std::ceil(b.upper()) - 1 : std::floor(b.upper())));
  return pythonFloat(b.upperOpen() ? std::nextafter(b.upper(), -std::numeric_limits<double>::infinity()) : b.upper());
}

}  // namespace

std::string tuningName(const std::string& parameter) {
  std::string name = parameter;
  const size_t slash = name.find('/');
  if (slash != std::string::npos) name[slash] = '_';
  return name;
}

std::string parameterName(const std::string& tuning_name) {
  for (const std::string& p : mild::runtimeParameterNames()) {
    if (tuningName(p) == tuning_name) return p;
  }
  throw mild::InvalidInput("dynamic_reconfigure parameter '" + tuning_name + "' is not a runtime parameter");
}

std::string tuningCfgScript() {
  std::ostringstream out;
  out << "#!/usr/bin/env python3\n"
         "# Generated at build time by generate_tuning_cfg from the parameter declarations (every one\n"
         "# declared Bounds::runtime()): do not edit, declare. The server starts from the node's own values.\n"
         "PACKAGE = \"mild_lcd\"\n\n"
         "from dynamic_reconfigure.parameter_generator_catkin import ParameterGenerator, double_t, int_t\n\n"
         "gen = ParameterGenerator()\n";
  const mild::DetectorParams defaults;
  mild::visitParameters(defaults, [&](const std::string& name, const auto& field, const mild::Bounds& bounds,
                                      const char* doc) {
    using T = std::decay_t<decltype(field)>;
    if (!bounds.isRuntime()) return;
    std::string type, value;
    constexpr bool integral = std::is_integral_v<T> && !std::is_same_v<T, bool>;
    if constexpr (integral) {
      type = "int_t";
      value = std::to_string(field);
    } else if constexpr (std::is_same_v<T, double>) {
      type = "double_t";
      value = pythonFloat(field);
    } else {
      throw mild::InvalidInput(name + " is declared runtime() but live tuning offers int and double parameters only");
    }
    out << "gen.add(\"" << tuningName(name) << "\", " << type << ", 0, " << pythonText(doc) << ", " << value;
    const std::string lo = lowest(bounds, integral), hi = highest(bounds, integral);
    if (!lo.empty()) out << ", min=" << lo;
    if (!hi.empty()) out << ", max=" << hi;
    out << ")\n";
  });
  out << "\nexit(gen.generate(PACKAGE, \"mild_lcd\", \"Tuning\"))\n";
  return out.str();
}

}  // namespace mild_lcd
