#pragma once

#include <string>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"

namespace mild {

// Theory of multi-index hashing for nearest-neighbour search of binary descriptors (seed paper
// III.B, for ORB's 256 bits; extended to any probe radius r and any width up to 512 bits).
//
// A stored feature and a query feature that differ in d bits meet in table t when their substrings
// t differ in at most r bits; they meet in the index when that holds for at least one of the m
// tables. P_recall(r, m, d) is the probability of that, under a model of where the d bits fall:
//
//  - kPaper: the paper's balls-in-bins idealisation. Each differing bit lands independently and
//    uniformly in one of m substrings (sampling with replacement; substrings have no length).
//  - kExact: the d differing bits are d distinct positions out of the width (sampling without
//    replacement) and substring t holds exactly SubstringLayout(m, bits).length(t) of them. This is what
//    MihIndex obeys when differing bits are spread uniformly over the descriptor.
//
// Both are computed exactly as 1 - P(every substring holds more than r differing bits), the
// complement counted with a generating function whose terms are all positive:
//   paper:  P(all > r) = d! / m^d   * [x^d] (sum_{k>r} x^k / k!)^m
//   exact:  P(all > r) = 1 / C(bits,d) * [x^d] prod_t sum_{k>r} C(l_t, k) x^k
// There is no alternating sum (inclusion-exclusion cancels catastrophically in floating point for
// large d and m), and the long double range holds 512! and 64^512, so nothing overflows.
enum class BitModel { kPaper, kExact };

BitModel bitModelFromName(const std::string& name);  // "paper" or "exact"; throws InvalidInput
std::string bitModelName(BitModel model);

// P_recall(r, m, d) for d = 0..bits (index d). Throws InvalidInput unless 1 <= m <= bits <= 512, 0 <= r.
std::vector<double> recallCurve(int r, int m, BitModel model, int bits = 256);
double recallProbability(int r, int m, int d, BitModel model, int bits = 256);

// The same for r = 0 by inclusion-exclusion over empty bins (the paper's own formula, in the
// balls-in-bins model): 1 - sum_j (-1)^j C(m, j) (1 - j/m)^d. Exact in real arithmetic, but it
// loses all precision in floating point once the terms dwarf the result; kept as a cross-check.
double recallByInclusionExclusion(int m, int d);

// A distribution of Hamming distances between descriptors of `bits` bits, over d = 0..bits.
struct DistancePrior {
  std::vector<double> p;  // bits + 1 probabilities summing to 1

  // A normal N(mean, stddev^2) discretised to the integers 0..bits and renormalised.
  static DistancePrior normal(double mean, double stddev, int bits = 256);
  // Normalised counts (bits + 1 of them, or fewer: the rest are zero). Throws InvalidInput when the
  // counts are negative or all zero.
  static DistancePrior fromCounts(const std::vector<double>& counts, int bits = 256);
  int bits() const { return static_cast<int>(p.size()) - 1; }
  double mean() const;
};

// The paper's ORB priors: inlier distances N(32, 10^2), outlier distances N(128, 20^2) (10 and 20
// read as standard deviations).
DistancePrior paperInlierPrior();
DistancePrior paperOutlierPrior();

struct MihCost {
  int m = 0;
  int r = 0;
  double accuracy = 0.0;    // R(r, m) = sum_d P_recall(r, m, d) P_i(d)
  double complexity = 0.0;  // E(r, m) = sum_d P_recall(r, m, d) P_o(d)
  double fixed_cost = 0.0;  // E_fixed(m): buckets to set up, sum_t 2^{l_t} (m 2^{bits/m} when m | bits)
  double probes = 0.0;      // buckets probed per query feature: sum_t sum_{k<=r} C(l_t, k)
};

// The width is the priors' (both must have the same).
MihCost analyse(int r, int m, const DistancePrior& inliers, const DistancePrior& outliers, BitModel model);
double fixedCost(int m, int bits = 256);

// The R/E/E_fixed table over m in [m_min, m_max] and r in [r_min, r_max].
std::vector<MihCost> analyseGrid(int m_min, int m_max, int r_min, int r_max, const DistancePrior& inliers,
                                 const DistancePrior& outliers, BitModel model);

// For each r of the grid, the smallest m whose accuracy reaches min_accuracy (R grows with m), in
// order of r; an r that never reaches it is left out.
std::vector<MihCost> smallestTablesReaching(const std::vector<MihCost>& grid, double min_accuracy);

// Which of those candidates costs least:
//  - offline (tables built once, memory no object): cost = E, the outliers visited per stored feature;
//  - online (tables live in memory and are set up as the map grows): cost = E * database_features
//    + E_fixed, outliers visited per query feature plus buckets to hold.
struct Recommendation {
  MihCost choice;
  double cost = 0.0;
  std::vector<MihCost> candidates;
  std::string explanation;  // one line
};
Recommendation recommend(const std::vector<MihCost>& grid, double min_accuracy, bool online, double database_features);

}  // namespace mild
