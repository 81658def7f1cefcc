#include "mild_lcd/params/parameter_spec.hpp"

#include <cmath>
#include <sstream>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

std::string number(double v) {
  std::ostringstream out;
  out.precision(15);
  out << v;
  return out.str();
}

}  // namespace

Bounds Bounds::any() { return Bounds{}; }

Bounds Bounds::atLeast(double lo) {
  Bounds b;
  b.lo_ = lo;
  return b;
}

Bounds Bounds::above(double lo) {
  Bounds b = atLeast(lo);
  b.lo_open_ = true;
  return b;
}

Bounds Bounds::in(double lo, double hi) {
  Bounds b;
  b.lo_ = lo;
  b.hi_ = hi;
  return b;
}

Bounds Bounds::aboveUpTo(double lo, double hi) {
  Bounds b = in(lo, hi);
  b.lo_open_ = true;
  return b;
}

Bounds Bounds::between(double lo, double hi) {
  Bounds b = aboveUpTo(lo, hi);
  b.hi_open_ = true;
  return b;
}

Bounds Bounds::oneOf(std::vector<std::string> choices) {
  Bounds b;
  b.choices_ = std::move(choices);
  return b;
}

Bounds Bounds::list(size_t min_items, size_t max_items, Bounds each) {
  Bounds b;
  b.is_list_ = true;
  b.min_items_ = min_items;
  b.max_items_ = max_items;
  b.each_.push_back(std::move(each));
  return b;
}

Bounds Bounds::orZero() const {
  Bounds b = *this;
  b.zero_ = true;
  return b;
}

Bounds Bounds::runtime() const {
  Bounds b = *this;
  b.runtime_ = true;
  return b;
}

bool Bounds::contains(double v) const {
  if (!std::isfinite(v)) return false;
  if (zero_ && v == 0.0) return true;
  if (lo_open_ ? !(v > lo_) : !(v >= lo_)) return false;
  if (hi_open_ ? !(v < hi_) : !(v <= hi_)) return false;
  return true;
}

std::string Bounds::text() const {
  if (!choices_.empty()) {
    std::string out;
    for (size_t i = 0; i < choices_.size(); ++i) {
      out += (i == 0 ? "" : i + 1 == choices_.size() ? " or " : ", ") + choices_[i];
    }
    return out;
  }
  if (is_list_) {
    std::string count = min_items_ == max_items_ ? std::to_string(min_items_)
                                                 : std::to_string(min_items_) + " to " + std::to_string(max_items_);
    const std::string each = each_.front().text();
    return count + " numbers" + (each.empty() ? "" : ", each " + each);
  }
  const bool has_lo = std::isfinite(lo_), has_hi = std::isfinite(hi_);
  std::string range;
  if (has_lo && has_hi) {
    range = (lo_open_ ? "(" : "[") + number(lo_) + ", " + number(hi_) + (hi_open_ ? ")" : "]");
  } else if (has_lo) {
    range = (lo_open_ ? "> " : ">= ") + number(lo_);
  } else if (has_hi) {
    range = (hi_open_ ? "< " : "<= ") + number(hi_);
  }
  if (zero_ && !range.empty()) range = "0 or " + range;
  return range;
}

void Bounds::check(const std::string& name, double value) const {
  if (!contains(value)) {
    const std::string range = text();
    throw InvalidInput(name + " must be " + (range.empty() ? "a finite number" : range) + ", got " + number(value));
  }
}

void Bounds::checkInteger(const std::string& name, long double value) const {
  const double v = static_cast<double>(value);
  if (!contains(v)) throw InvalidInput(name + " must be " + text() + ", got " + number(v));
}

void Bounds::check(const std::string& name, const std::string& value) const {
  if (choices_.empty()) return;
  for (const std::string& c : choices_) {
    if (c == value) return;
  }
  throw InvalidInput(name + " must be " + text() + ", got '" + value + "'");
}

void Bounds::check(const std::string& name, const std::vector<double>& value) const {
  if (is_list_ && (value.size() < min_items_ || value.size() > max_items_)) {
    throw InvalidInput(name + " must list " + text() + ", got " + std::to_string(value.size()));
  }
  const Bounds& each = is_list_ ? each_.front() : Bounds{};
  for (double v : value) {
    if (!each.contains(v)) {
      throw InvalidInput(name + " must list " + text() + ", got the item " + number(v));
    }
  }
}

}  // namespace mild
