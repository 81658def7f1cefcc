#pragma once

// The temporal stage of the detector: it turns each keyframe's similarity vector into a loop
// probability per stored keyframe, using what earlier keyframes showed (temporal coherence). The
// detector owns one through this interface; which one is a parameter (filter/type, one of the
// table in filter/filters.hpp, each with its own parameter section), and the database file records
// it, so that a saved run is only resumed by the filter that wrote it.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace mild {

// The names filter/type accepts (the entries of filter/filters.hpp).
const std::vector<std::string>& temporalFilterTypes();

class TemporalFilter {
 public:
  virtual ~TemporalFilter() = default;

  // Recorded in database files; a saved state is only loaded into a filter of the same name.
  virtual const char* name() const = 0;

  // Advances one keyframe. similarity[j] is the current keyframe's similarity to eligible keyframe
  // j; the eligible set is a prefix of the database that may grow or shrink between calls (what
  // lies beyond a shorter prefix is forgotten). Returns the loop probability of every eligible
  // keyframe. Causal: nothing returned for an earlier keyframe is ever revised.
  virtual const std::vector<double>& update(const std::vector<double>& similarity) = 0;
  virtual const std::vector<double>& loopProbability() const = 0;
  // How many keyframes the state covers (the eligible prefix of the last update).
  virtual size_t stateKeyframes() const = 0;
  virtual void reset() = 0;
  // What the last update judged the keyframes by, when it is not the similarity it was given (a
  // filter that corrects its input: HubCorrectedFilter); nullptr when it is the similarity. The
  // detector draws its candidates and their saliency from the same values the filter weighed.
  virtual const std::vector<double>* evidence() const { return nullptr; }
  // The bytes its state holds (a few numbers per keyframe: the map's memory counts them beside the
  // database's).
  virtual size_t memoryBytes() const = 0;

  // The state as bytes and back, bit-exact (a resumed run continues exactly). loadState throws
  // InvalidInput, changing nothing, for bytes that are not a state of this filter.
  virtual std::vector<uint8_t> saveState() const = 0;
  virtual void loadState(const std::vector<uint8_t>& bytes) = 0;
};

// Robust standardisation of a similarity vector: (s - median) / (1.4826 MAD), falling back to the
// mean absolute deviation from the median when more than half the values are equal, and to all
// zeros when every value is equal.
std::vector<double> robustSaliency(const std::vector<double>& similarity);

}  // namespace mild
