#pragma once

// Each parameter is declared once, beside the struct that holds it: its name, its field (whose
// initialiser is the default), its bounds and what it means. Validation, the YAML and ROS loaders,
// --print-config, config/default.yaml and the README's tables all come from that declaration.
//
//   struct OrbParams {
//     int num_features = 800;
//     static constexpr const char* kSection = "orb";
//     template <class Self, class Visit>
//     static void declare(Self& p, Visit&& v) {
//       v("num_features", p.num_features, Bounds::atLeast(1), "upper bound per keyframe");
//     }
//     void validate() const { validateDeclared(*this); }
//   };

#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

namespace mild {

// What values a parameter may take.
class Bounds {
 public:
  // Any finite number, any string, any list of finite numbers.
  static Bounds any();
  static Bounds atLeast(double lo);               // >= lo
  static Bounds above(double lo);                 // > lo
  static Bounds in(double lo, double hi);         // [lo, hi]
  static Bounds aboveUpTo(double lo, double hi);  // (lo, hi]
  static Bounds between(double lo, double hi);    // (lo, hi)
  static Bounds probability() { return in(0.0, 1.0); }
  static Bounds oneOf(std::vector<std::string> choices);
  // A list of min_items..max_items numbers, each within `each`.
  static Bounds list(size_t min_items, size_t max_items, Bounds each);

  // 0 is allowed besides the range (0 = off, or automatic: the doc says which).
  Bounds orZero() const;
  // The parameter may change while the detector runs (LoopDetector::retune, dynamic_reconfigure):
  // it only decides how candidates are chosen, checked and reported.
  Bounds runtime() const;

  bool isRuntime() const { return runtime_; }
  // The numeric range, for what describes a parameter elsewhere (the generated dynamic_reconfigure
  // cfg): -inf/+inf when unbounded on that side.
  double lower() const { return lo_; }
  double upper() const { return hi_; }
  bool lowerOpen() const { return lo_open_; }
  bool upperOpen() const { return hi_open_; }
  bool allowsZero() const { return zero_; }
  bool contains(double value) const;
  // "[4, 64]", ">= 1", "0 or [4, 64]", "(0, 1)", "orb, brisk or akaze", "5 numbers >= 0", "".
  std::string text() const;

  // Throw InvalidInput "NAME must be TEXT, got VALUE" unless the value fits.
  void check(const std::string& name, double value) const;
  void check(const std::string& name, const std::string& value) const;
  void check(const std::string& name, const std::vector<double>& value) const;
  void check(const std::string&, bool) const {}
  template <class T, std::enable_if_t<std::is_integral_v<T> && !std::is_same_v<T, bool>, int> = 0>
  void check(const std::string& name, T value) const {
    checkInteger(name, static_cast<long double>(value));
  }
  template <class T, std::enable_if_t<std::is_enum_v<T>, int> = 0>
  void check(const std::string&, T) const {}  // an enum is parsed from oneOf's choices

 private:
  void checkInteger(const std::string& name, long double value) const;
  double lo_ = -std::numeric_limits<double>::infinity();
  double hi_ = std::numeric_limits<double>::infinity();
  bool lo_open_ = false, hi_open_ = false;
  bool zero_ = false;
  bool runtime_ = false;
  std::vector<std::string> choices_;
  bool is_list_ = false;
  size_t min_items_ = 0, max_items_ = 0;
  std::vector<Bounds> each_;  // the list elements' bounds (one), empty otherwise
};

// Calls S::declare on a struct (const or not) and checks every declared field against its bounds,
// naming it "<S::kSection>/<name>". Throws InvalidInput at the first that does not fit.
template <class S>
void validateDeclared(const S& params) {
  S::declare(params, [](const char* name, const auto& field, const Bounds& bounds, const char*) {
    bounds.check(std::string(S::kSection) + "/" + name, field);
  });
}

// Visits the declared fields of one section with their full names ("<section>/<name>").
template <class S, class Visit>
void visitSection(S& params, Visit&& visit) {
  using Plain = std::remove_const_t<S>;
  Plain::declare(params, [&](const char* name, auto& field, const Bounds& bounds, const char* doc) {
    visit(std::string(Plain::kSection) + "/" + name, field, bounds, doc);
  });
}

}  // namespace mild
