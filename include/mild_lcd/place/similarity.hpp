#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"

namespace mild {

// Image similarity by voting (seed paper III.A, III.C-D).
//
//   phi(f, g)  = exp(-d^2 / sigma2)  for Hamming distance d <= max_distance (d0), else 0
//   phi'(f, g) = log(N / N_f) * phi(f, g) / (sum_{h in Omega_f} phi(f, h) + burstiness_regularizer)
//   Phi'(I_q, I_k) = sum_{f in I_q} sum_{g in Omega_f, g in I_k} phi'(f, g)   [/ (|F_q| |F_k|)]
//
// Omega_f is the candidate set of query feature f (features that meet f in at least one hash table
// and lie within d0; every stored feature within d0 in exact mode), N the number of keyframes that
// may be candidates and N_f how many of them own at least one feature of Omega_f. The inverse
// document frequency log(N / N_f) silences features that are everywhere (inter-image burstiness);
// dividing by the feature's total vote mass keeps one query feature from voting more than once.
struct SimilarityParams {
  int max_distance = 64;  // d0
  double sigma2 = 900.0;  // sigma^2 in phi
  // The two halves of inter-image burstiness handling; both on is the paper's phi'.
  bool idf_weighting = true;       // the log(N / N_f) factor
  bool vote_normalization = true;  // the division by the feature's vote mass
  // Added to the vote mass of every query feature, so that a lone weak match does not get the
  // weight of a perfect one. 0 gives the paper's formula exactly.
  double burstiness_regularizer = 0.0;
  // Divide by |F_q| |F_k| as in the paper's Phi' (useful without burstiness weighting, which already
  // normalises per query feature).
  bool normalize_by_feature_counts = false;
  // Early termination (seed paper III.E): a candidate whose distance on the first 64 bits exceeds
  // this is rejected without reading the other 192 bits. Values >= max_distance never change a score.
  int early_termination_threshold = 20;

  // Throws InvalidInput naming the first invalid field.
  void validate() const;
};

// phi(d) for d = 0..256, precomputed.
class PhiTable {
 public:
  explicit PhiTable(const SimilarityParams& params);
  double operator()(int distance) const { return table_[distance]; }

 private:
  std::array<double, kDescriptorBits + 1> table_{};
};

}  // namespace mild
