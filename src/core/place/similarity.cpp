#include "mild_lcd/place/similarity.hpp"

#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

SimilarityParams SimilarityParams::scaledTo(int bits) const {
  SimilarityParams scaled = *this;
  scaled.max_distance = scaleDistance(max_distance, bits);
  const double ratio = static_cast<double>(bits) / 256.0;
  scaled.sigma2 = sigma2 * ratio * ratio;
  return scaled;
}

PhiTable::PhiTable(const SimilarityParams& params) {
  for (int d = 0; d <= kMaxDescriptorBits; ++d) {
    table_[d] = d <= params.max_distance ? std::exp(-static_cast<double>(d) * d / params.sigma2) : 0.0;
  }
}

}  // namespace mild
