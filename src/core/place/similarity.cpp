#include "mild_lcd/place/similarity.hpp"

#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

void SimilarityParams::validate() const {
  if (max_distance < 0 || max_distance > kDescriptorBits) {
    throw InvalidInput("similarity/max_distance (d0) must be in [0, 256], got " + std::to_string(max_distance));
  }
  if (!(sigma2 > 0.0) || !std::isfinite(sigma2)) {
    throw InvalidInput("similarity/sigma2 must be a positive number, got " + std::to_string(sigma2));
  }
  if (!(burstiness_regularizer >= 0.0) || !std::isfinite(burstiness_regularizer)) {
    throw InvalidInput("similarity/burstiness_regularizer must be >= 0, got " + std::to_string(burstiness_regularizer));
  }
  if (early_termination_threshold < 0 || early_termination_threshold > 64) {
    throw InvalidInput(
        "similarity/early_termination_threshold must be in [0, 64] (bits of the first 64-bit word), got " +
        std::to_string(early_termination_threshold));
  }
}

PhiTable::PhiTable(const SimilarityParams& params) {
  for (int d = 0; d <= kDescriptorBits; ++d) {
    table_[d] = d <= params.max_distance ? std::exp(-static_cast<double>(d) * d / params.sigma2) : 0.0;
  }
}

}  // namespace mild
