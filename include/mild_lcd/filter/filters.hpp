#pragma once

// The temporal filters filter/type can name: one entry each. An entry is a TemporalFilter with
// kName (recorded in database files), Params (its parameter section, declared beside it and named
// after it: exclusive_hypotheses/, independent_binary/) and a constructor (const Params&).
// Adding a filter: its file, its entry here, CMake, its test.

#include <memory>
#include <string>
#include <tuple>

#include "mild_lcd/common/registry.hpp"
#include "mild_lcd/filter/exclusive_hypothesis_filter.hpp"
#include "mild_lcd/filter/independent_binary_filter.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

namespace mild {

using TemporalFilters = Registry<ExclusiveHypothesisFilter, IndependentBinaryFilter>;

// Which filter runs (filter/type) and every filter's own section (`filters`: one per entry).
struct FilterParams {
  std::string type = ExclusiveHypothesisFilter::kName;
  int hubness_min_queries = 0;
  TemporalFilters::Sections filters;

  static constexpr const char* kSection = "filter";
  static constexpr const char* kDoc = "The temporal filter that turns similarity into a loop probability.";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("type", p.type, Bounds::oneOf(temporalFilterTypes()),
      "The temporal filter, exclusive_hypotheses or independent_binary (each a section below), which alone resumes "
      "a map it saved.");
    v("hubness_min_queries", p.hubness_min_queries, Bounds::in(0, 1000000),
      "Queries a keyframe must have been compared with before the filter judges it by its saliency less its "
      "hubness, the median saliency it had for them (queries, 0 = off, up to 1,000,000).");
  }

  // A filter's section, e.g. section<ExclusiveHypothesisParams>().loop_onset.
  template <class S>
  S& section() {
    return std::get<S>(filters);
  }
  template <class S>
  const S& section() const {
    return std::get<S>(filters);
  }
  void validate() const;  // throws InvalidInput naming the first invalid field
};

// The filter params.type names, with its section's parameters; throws InvalidInput for an unknown
// type or invalid parameters.
std::unique_ptr<TemporalFilter> makeTemporalFilter(const FilterParams& params);

}  // namespace mild
