#include "mild_lcd/filter/independent_binary_filter.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/filter/filter_state.hpp"

namespace mild {

IndependentBinaryFilter::IndependentBinaryFilter(const Params& params) : params_((params.validate(), params)) {}

const std::vector<double>& IndependentBinaryFilter::update(const std::vector<double>& similarity) {
  const size_t n = similarity.size();
  previous_ = probability_;
  previous_.resize(n, 0.0);  // newly eligible keyframes start at "no loop"
  probability_.assign(n, 0.0);
  if (n == 0) return probability_;
  double mean = 0.0;
  for (double s : similarity) mean += s;
  mean /= static_cast<double>(n);
  double variance = 0.0;
  for (double s : similarity) variance += (s - mean) * (s - mean);
  const double sigma = std::sqrt(variance / std::max<double>(1.0, static_cast<double>(n) - 1.0));
  const double persistence = params_.loop_persistence;
  for (size_t j = 0; j < n; ++j) {
    double alpha = 0.0;
    for (size_t k = j >= 2 ? j - 2 : 0; k < std::min(n, j + 3); ++k) alpha = std::max(alpha, previous_[k]);
    const double prior = alpha * persistence + (1.0 - alpha) * (1.0 - persistence);
    const double saliency = mean > 1e-12 ? (similarity[j] - sigma) / mean : 0.0;
    const double likelihood = std::isfinite(saliency) ? std::max(1.0, saliency) : 1.0;
    const double loop = likelihood * prior;
    probability_[j] = loop / (loop + params_.no_loop_likelihood * (1.0 - prior));
  }
  return probability_;
}

std::vector<uint8_t> IndependentBinaryFilter::saveState() const { return packFilterState(probability_); }

void IndependentBinaryFilter::loadState(const std::vector<uint8_t>& bytes) {
  std::vector<double> p = unpackFilterState(bytes, 0).values;
  for (double v : p) {
    if (!(v >= 0.0 && v <= 1.0)) throw InvalidInput("filter state holds a value outside [0, 1]");
  }
  probability_ = std::move(p);
}

}  // namespace mild
