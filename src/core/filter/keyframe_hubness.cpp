#include "mild_lcd/filter/keyframe_hubness.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/filter/temporal_filter.hpp"

namespace mild {

namespace {
constexpr uint32_t kStateTag = 0x31425548;  // "HUB1"

int binOf(double z) {
  if (!std::isfinite(z)) return 0;
  const double b = std::floor((z - KeyframeHubness::kLowest) / KeyframeHubness::kBinWidth);
  return static_cast<int>(std::clamp(b, 0.0, static_cast<double>(KeyframeHubness::kBins - 1)));
}
}  // namespace

KeyframeHubness::KeyframeHubness(int min_queries) : min_queries_(std::max(1, min_queries)) {}

double KeyframeHubness::hubness(size_t keyframe) const {
  if (keyframe >= counts_.size() || counts_[keyframe] < static_cast<uint32_t>(min_queries_)) return 0.0;
  const uint16_t* h = bins_.data() + keyframe * kBins;
  uint32_t total = 0;
  for (int b = 0; b < kBins; ++b) total += h[b];
  if (total == 0) return 0.0;
  // The median, interpolated within its bin.
  const double half = 0.5 * total;
  double below = 0.0;
  for (int b = 0; b < kBins; ++b) {
    if (below + h[b] >= half) {
      const double within = h[b] > 0 ? (half - below) / h[b] : 0.0;
      return kLowest + (b + within) * kBinWidth;
    }
    below += h[b];
  }
  return kLowest + kBins * kBinWidth;
}

std::vector<double> KeyframeHubness::correct(const std::vector<double>& similarity) {
  const size_t n = similarity.size();
  std::vector<double> z = robustSaliency(similarity);
  counts_.resize(n, 0);
  bins_.resize(n * kBins, 0);
  for (size_t j = 0; j < n; ++j) {
    const double hub = hubness(j);  // of the earlier queries, before this one is recorded
    uint16_t* h = bins_.data() + j * kBins;
    uint16_t& bin = h[binOf(z[j])];
    if (bin == std::numeric_limits<uint16_t>::max()) {  // keep the shape, forget half the weight
      for (int b = 0; b < kBins; ++b) h[b] = static_cast<uint16_t>(h[b] / 2);
    }
    ++bin;
    if (counts_[j] < std::numeric_limits<uint32_t>::max()) ++counts_[j];
    z[j] -= hub;
  }
  return z;
}

void KeyframeHubness::reset() {
  bins_.clear();
  counts_.clear();
}

size_t KeyframeHubness::stateBytes(size_t keyframes) {
  return 2 * sizeof(uint32_t) + keyframes * (sizeof(uint32_t) + kBins * sizeof(uint16_t));
}

void KeyframeHubness::appendState(std::vector<uint8_t>& bytes) const {
  const size_t start = bytes.size();
  bytes.resize(start + stateBytes(counts_.size()));
  uint8_t* out = bytes.data() + start;
  const uint32_t tag = kStateTag, n = static_cast<uint32_t>(counts_.size());
  std::memcpy(out, &tag, sizeof tag);
  std::memcpy(out + 4, &n, sizeof n);
  std::memcpy(out + 8, counts_.data(), n * sizeof(uint32_t));
  std::memcpy(out + 8 + n * sizeof(uint32_t), bins_.data(), bins_.size() * sizeof(uint16_t));
}

void KeyframeHubness::readState(const uint8_t* data, size_t size) {
  uint32_t tag = 0, n = 0;
  if (size < 8) throw InvalidInput("keyframe hubness state too short");
  std::memcpy(&tag, data, sizeof tag);
  std::memcpy(&n, data + 4, sizeof n);
  if (tag != kStateTag) throw InvalidInput("keyframe hubness state has an unknown tag");
  if (size != stateBytes(n)) {
    throw InvalidInput("keyframe hubness state of " + std::to_string(size) + " bytes does not hold " +
                       std::to_string(n) + " keyframes");
  }
  std::vector<uint32_t> counts(n);
  Histogram bins(static_cast<size_t>(n) * kBins);
  std::memcpy(counts.data(), data + 8, n * sizeof(uint32_t));
  std::memcpy(bins.data(), data + 8 + n * sizeof(uint32_t), bins.size() * sizeof(uint16_t));
  counts_ = std::move(counts);
  bins_ = std::move(bins);
}

}  // namespace mild
