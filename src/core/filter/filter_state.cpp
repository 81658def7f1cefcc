#include "mild_lcd/filter/filter_state.hpp"

#include <cstring>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

std::vector<uint8_t> packFilterState(const std::vector<double>& values, const std::vector<double>& extra) {
  const uint32_t n = static_cast<uint32_t>(values.size());
  std::vector<uint8_t> out(sizeof(n) + (values.size() + extra.size()) * sizeof(double));
  std::memcpy(out.data(), &n, sizeof(n));
  if (!values.empty()) std::memcpy(out.data() + sizeof(n), values.data(), values.size() * sizeof(double));
  if (!extra.empty()) {
    std::memcpy(out.data() + sizeof(n) + values.size() * sizeof(double), extra.data(), extra.size() * sizeof(double));
  }
  return out;
}

FilterStateValues unpackFilterState(const std::vector<uint8_t>& bytes, size_t extra) {
  uint32_t n = 0;
  if (bytes.size() < sizeof(n) + extra * sizeof(double)) throw InvalidInput("filter state too short");
  std::memcpy(&n, bytes.data(), sizeof(n));
  if (bytes.size() != sizeof(n) + (static_cast<size_t>(n) + extra) * sizeof(double)) {
    throw InvalidInput("filter state of " + std::to_string(bytes.size()) + " bytes does not hold " + std::to_string(n) +
                       " probabilities");
  }
  FilterStateValues out;
  out.values.resize(n);
  out.extra.resize(extra);
  if (n > 0) std::memcpy(out.values.data(), bytes.data() + sizeof(n), n * sizeof(double));
  if (extra > 0) std::memcpy(out.extra.data(), bytes.data() + sizeof(n) + n * sizeof(double), extra * sizeof(double));
  return out;
}

}  // namespace mild
