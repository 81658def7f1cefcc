#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "mild_lcd/features/features.hpp"
#include "mild_lcd/index/mih_index.hpp"
#include "mild_lcd/offline/mih_analysis.hpp"

namespace mild {

// Hamming-distance priors measured on the user's own images, for the MIH analysis
// (mih_analysis.hpp), in place of the paper's N(32, 10) / N(128, 20).
//
// Inliers: features of two overlapping views matched by exact nearest neighbour (brute force, Lowe
// ratio 0.8) and kept when they agree with a fundamental matrix fitted by MAGSAC. The matching is
// exhaustive on purpose: pairs found through MIH would over-represent the ones MIH finds.
// Outliers: each feature of one view paired with a random feature of a view that does not overlap.
struct PriorMeasurementParams {
  double ratio = 0.8;
  double ransac_threshold = 1.0;  // pixels
  int min_inliers = 20;           // an overlapping pair with fewer model inliers contributes nothing
  uint64_t seed = 1;              // of the random outlier pairing
};

struct FeaturePair {
  const Features* a = nullptr;
  const Features* b = nullptr;
};

struct MeasuredPriors {
  int bits = 256;                      // the views' descriptor width
  std::vector<double> inlier_counts;   // bits + 1 bins, d = 0..bits
  std::vector<double> outlier_counts;  // bits + 1 bins
  size_t overlapping_pairs_used = 0;   // overlapping pairs that reached min_inliers
  // Every inlier correspondence found (query descriptor, stored descriptor), for validating the
  // analysis against the real index.
  std::vector<std::pair<Descriptor, Descriptor>> inlier_descriptors;

  DistancePrior inliers() const { return DistancePrior::fromCounts(inlier_counts, bits); }
  DistancePrior outliers() const { return DistancePrior::fromCounts(outlier_counts, bits); }
};

// Any descriptor width, the same for every view. Throws InvalidInput when a view's keypoints and
// descriptors differ in number, or views differ in width.
MeasuredPriors measureDistancePriors(const std::vector<FeaturePair>& overlapping,
                                     const std::vector<FeaturePair>& disjoint,
                                     const PriorMeasurementParams& params = {});

// The fraction of correspondences (query, stored) that the real MihIndex with these parameters
// finds: each stored descriptor is indexed as its own keyframe and each query probes the index.
// This is what R(r, m) predicts from the correspondences' distance histogram.
double indexRecall(const std::vector<std::pair<Descriptor, Descriptor>>& correspondences, MihParams params);

}  // namespace mild
