#pragma once

// A keyframe that resembles everything -- foliage, a textured floor, a dark frame whose few corners
// match anywhere -- is the most similar keyframe to many queries that are not its place, and the
// temporal filter follows it. On gp_night_a one keyframe was the best candidate of 43 of 159 queries,
// every one with its loop elsewhere. The paper's IDF discounts a *word* seen in many images; this is
// the same idea one level up: a keyframe's hubness is the median of the saliency (the robust z of its
// similarity among a query's eligible keyframes, robustSaliency) it had for the queries it was
// compared with before, and the filter judges each keyframe by its saliency minus its hubness. The
// median, not the mean, so that the stretch of queries that truly revisit a keyframe (a corridor
// walked again: tens of queries in a row) does not make a hub of it.
//
// Kept in constant memory per keyframe: a histogram of its past saliencies (kBins bins of kBinWidth
// from kLowest; values beyond either end count in the end bin), halved when a bin would overflow.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace mild {

class KeyframeHubness {
 public:
  static constexpr int kBins = 64;
  static constexpr double kLowest = -2.0;
  static constexpr double kBinWidth = 0.25;

  // A keyframe is corrected once it has been compared with at least `min_queries` queries (>= 1).
  explicit KeyframeHubness(int min_queries);

  // The similarity vector the filter should judge this query by: robustSaliency(similarity) minus
  // each keyframe's hubness (0 until it has min_queries earlier saliencies); then records this
  // query's saliencies. Keyframes beyond similarity.size() are forgotten (a cut database), as the
  // filters forget them.
  std::vector<double> correct(const std::vector<double>& similarity);

  // The keyframe's hubness now (0 when it has fewer than min_queries saliencies or is unknown).
  double hubness(size_t keyframe) const;
  size_t keyframes() const { return counts_.size(); }
  void reset();

  // Appended to / read from a filter's saved state. read takes the bytes it wrote and throws
  // InvalidInput, changing nothing, when they are not a hubness state.
  void appendState(std::vector<uint8_t>& bytes) const;
  void readState(const uint8_t* data, size_t size);
  // The size of the state of `keyframes` keyframes.
  static size_t stateBytes(size_t keyframes);
  size_t memoryBytes() const {
    return bins_.capacity() * sizeof(Histogram::value_type) + counts_.capacity() * sizeof(uint32_t);
  }

 private:
  using Histogram = std::vector<uint16_t>;  // kBins counts per keyframe, contiguous
  int min_queries_;
  Histogram bins_;
  std::vector<uint32_t> counts_;  // saliencies in each keyframe's histogram
};

}  // namespace mild
