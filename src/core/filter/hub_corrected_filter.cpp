#include "mild_lcd/filter/hub_corrected_filter.hpp"

#include <cstring>
#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

HubCorrectedFilter::HubCorrectedFilter(std::unique_ptr<TemporalFilter> filter, int min_queries)
    : filter_(std::move(filter)),
      name_(std::string(filter_->name()) + "+hubness"),
      min_queries_(min_queries),
      hubness_(min_queries) {}

const std::vector<double>& HubCorrectedFilter::update(const std::vector<double>& similarity) {
  evidence_ = hubness_.correct(similarity);
  return filter_->update(evidence_);
}

void HubCorrectedFilter::reset() {
  filter_->reset();
  hubness_.reset();
  evidence_.clear();
}

std::vector<uint8_t> HubCorrectedFilter::saveState() const {
  const std::vector<uint8_t> inner = filter_->saveState();
  const uint64_t size = inner.size();
  std::vector<uint8_t> bytes(sizeof size + inner.size());
  std::memcpy(bytes.data(), &size, sizeof size);
  if (!inner.empty()) std::memcpy(bytes.data() + sizeof size, inner.data(), inner.size());
  hubness_.appendState(bytes);
  return bytes;
}

void HubCorrectedFilter::loadState(const std::vector<uint8_t>& bytes) {
  uint64_t size = 0;
  if (bytes.size() < sizeof size) throw InvalidInput("hub-corrected filter state too short");
  std::memcpy(&size, bytes.data(), sizeof size);
  if (size > bytes.size() - sizeof size) {
    throw InvalidInput("hub-corrected filter state names " + std::to_string(size) + " bytes of the filter's in " +
                       std::to_string(bytes.size()));
  }
  const auto inner_begin = bytes.begin() + static_cast<long>(sizeof size);
  const auto inner_end = inner_begin + static_cast<long>(size);
  // Both read before either is kept: a refused state changes nothing.
  KeyframeHubness hubness(min_queries_);
  hubness.readState(bytes.data() + sizeof size + size, bytes.size() - sizeof size - size);
  filter_->loadState(std::vector<uint8_t>(inner_begin, inner_end));
  hubness_ = std::move(hubness);
  evidence_.clear();
}

}  // namespace mild
