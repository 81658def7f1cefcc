#include "mild_lcd/filter/temporal_filter.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/median.hpp"
#include "mild_lcd/filter/exclusive_hypothesis_filter.hpp"
#include "mild_lcd/filter/independent_binary_filter.hpp"

namespace mild {

const std::vector<std::string>& temporalFilterTypes() {
  static const std::vector<std::string> types = {ExclusiveHypothesisFilter::kName, IndependentBinaryFilter::kName};
  return types;
}

void FilterParams::validate() const {
  validateDeclared(*this);
  double total = 0.0;
  for (double w : motion_kernel) total += w;
  if (!(total > 0.0)) throw InvalidInput("filter/motion_kernel needs at least one positive weight");
}

std::unique_ptr<TemporalFilter> makeTemporalFilter(const FilterParams& params) {
  params.validate();
  if (params.type == IndependentBinaryFilter::kName) return std::make_unique<IndependentBinaryFilter>(params);
  return std::make_unique<ExclusiveHypothesisFilter>(params);
}

double noLoopLikelihood(const FilterParams& params, size_t eligible_keyframes) {
  if (params.no_loop_growth == 0.0) return params.no_loop_likelihood;
  const double ratio = static_cast<double>(eligible_keyframes) / params.no_loop_reference_keyframes;
  return std::max(1.0, params.no_loop_likelihood * std::pow(ratio, params.no_loop_growth));
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
