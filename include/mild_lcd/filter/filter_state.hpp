#pragma once

// The layout of every temporal filter's saved state (TemporalFilter::saveState), written once: u32
// count, `count` doubles, then a fixed number of further doubles (the exclusive-hypothesis filter's
// no-loop probability: one; the independent filter: none). Native byte order, as the rest of the
// database file.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace mild {

struct FilterStateValues {
  std::vector<double> values;  // one per keyframe of the state
  std::vector<double> extra;   // the fixed tail
};

std::vector<uint8_t> packFilterState(const std::vector<double>& values, const std::vector<double>& extra = {});
// Throws InvalidInput ("filter state too short", "filter state of B bytes does not hold N
// probabilities") when `bytes` is not that layout with `extra` further doubles.
FilterStateValues unpackFilterState(const std::vector<uint8_t>& bytes, size_t extra);

}  // namespace mild
