#pragma once

// A temporal filter that judges each keyframe by its saliency with its hubness taken out
// (keyframe_hubness.hpp): filter/hubness_min_queries above 0 wraps the filter/type filter in it.
// Its name is the wrapped filter's with "+hubness", so that a map saved with the correction is
// resumed only with it (the hubness is part of the saved state) and one saved without it only
// without it.

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "mild_lcd/filter/keyframe_hubness.hpp"
#include "mild_lcd/filter/temporal_filter.hpp"

namespace mild {

class HubCorrectedFilter : public TemporalFilter {
 public:
  HubCorrectedFilter(std::unique_ptr<TemporalFilter> filter, int min_queries);
  const char* name() const override { return name_.c_str(); }

  const std::vector<double>& update(const std::vector<double>& similarity) override;
  const std::vector<double>& loopProbability() const override { return filter_->loopProbability(); }
  // Either part's: a loaded map refuses a state covering more keyframes than it holds.
  size_t stateKeyframes() const override { return std::max(filter_->stateKeyframes(), hubness_.keyframes()); }
  void reset() override;
  const std::vector<double>* evidence() const override { return &evidence_; }
  // The wrapped filter's state, then the hubness: u64 size of the first, its bytes, the hubness's.
  std::vector<uint8_t> saveState() const override;
  void loadState(const std::vector<uint8_t>& bytes) override;
  size_t memoryBytes() const override {
    return filter_->memoryBytes() + hubness_.memoryBytes() + evidence_.capacity() * sizeof(double);
  }

 private:
  std::unique_ptr<TemporalFilter> filter_;
  std::string name_;
  int min_queries_;
  KeyframeHubness hubness_;
  std::vector<double> evidence_;
};

}  // namespace mild
