#include "mild_lcd/filter/temporal_filter.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/median.hpp"
#include "mild_lcd/filter/filters.hpp"
#include "mild_lcd/filter/hub_corrected_filter.hpp"

namespace mild {

const std::vector<std::string>& temporalFilterTypes() {
  static const std::vector<std::string> types = TemporalFilters::names();
  return types;
}

void FilterParams::validate() const {
  validateDeclared(*this);
  forEachSection(filters, [](const auto& section) { section.validate(); });
}

std::unique_ptr<TemporalFilter> makeTemporalFilter(const FilterParams& params) {
  params.validate();
  std::unique_ptr<TemporalFilter> filter;
  TemporalFilters::withName(params.type, [&](auto entry) {
    using F = typename decltype(entry)::type;
    filter = std::make_unique<F>(params.section<typename F::Params>());
  });
  if (params.hubness_min_queries > 0) {
    filter = std::make_unique<HubCorrectedFilter>(std::move(filter), params.hubness_min_queries);
  }
  return filter;
}

std::vector<double> robustSaliency(const std::vector<double>& similarity) {
  std::vector<double> z(similarity.size(), 0.0);
  if (similarity.empty()) return z;
  std::vector<double> work = similarity;
  const double centre = median(work);
  double mean_abs = 0.0;
  for (size_t j = 0; j < similarity.size(); ++j) {
    work[j] = std::abs(similarity[j] - centre);
    mean_abs += work[j];
  }
  mean_abs /= static_cast<double>(similarity.size());
  double scale = 1.4826 * median(work);  // consistent with the standard deviation of a normal
  if (!(scale > 0.0)) scale = 1.2533 * mean_abs;
  if (!(scale > 0.0) || !std::isfinite(scale)) return z;
  for (size_t j = 0; j < similarity.size(); ++j) z[j] = (similarity[j] - centre) / scale;
  return z;
}

}  // namespace mild
