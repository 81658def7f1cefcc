#include "mild_lcd/filter/temporal_filter.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/filter/exclusive_hypothesis_filter.hpp"
#include "mild_lcd/filter/independent_binary_filter.hpp"

namespace mild {

const std::vector<std::string>& temporalFilterTypes() {
  static const std::vector<std::string> types = {ExclusiveHypothesisFilter::kName, IndependentBinaryFilter::kName};
  return types;
}

void FilterParams::validate() const {
  const auto& types = temporalFilterTypes();
  if (std::find(types.begin(), types.end(), type) == types.end()) {
    throw InvalidInput("filter/type must be 'exclusive_hypotheses' or 'independent_binary', got '" + type + "'");
  }
  auto probability = [](double v, const char* name) {
    if (!(v >= 0.0 && v <= 1.0))
      throw InvalidInput(std::string(name) + " must be a probability in [0, 1], got " + std::to_string(v));
  };
  probability(loop_persistence, "filter/loop_persistence");
  probability(loop_onset, "filter/loop_onset");
  if (motion_kernel.empty() || motion_kernel.size() > 64) {
    throw InvalidInput("filter/motion_kernel must list 1 to 64 weights (advancing 0, 1, 2, ... keyframes)");
  }
  double total = 0.0;
  for (double w : motion_kernel) {
    if (!(w >= 0.0) || !std::isfinite(w)) throw InvalidInput("filter/motion_kernel weights must be >= 0");
    total += w;
  }
  if (!(total > 0.0)) throw InvalidInput("filter/motion_kernel needs at least one positive weight");
  if (!(no_loop_likelihood > 0.0) || !std::isfinite(no_loop_likelihood)) {
    throw InvalidInput("filter/no_loop_likelihood must be a positive number, got " +
                       std::to_string(no_loop_likelihood));
  }
  if (candidate_window < 0)
    throw InvalidInput("filter/candidate_window must be >= 0, got " + std::to_string(candidate_window));
}

std::unique_ptr<TemporalFilter> makeTemporalFilter(const FilterParams& params) {
  params.validate();
  if (params.type == IndependentBinaryFilter::kName) return std::make_unique<IndependentBinaryFilter>(params);
  return std::make_unique<ExclusiveHypothesisFilter>(params);
}

namespace {

// Median with the two middle values averaged for an even count; reorders its argument.
double median(std::vector<double>& v) {
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(mid), v.end());
  const double upper = v[mid];
  if (v.size() % 2 == 1) return upper;
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + static_cast<long>(mid)));
}

}  // namespace

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
