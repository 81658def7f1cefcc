#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"
#include "mild_lcd/params/parameter_spec.hpp"

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
//
// Distances are given for ORB's 256 bits. A database of wider descriptors scales max_distance by
// bits / 256 and sigma2 by its square (scaledTo), since differing bits grow with the width: inlier
// pairs measured on pub_city differ in 38.6 +- 12.3 of ORB's 256 bits and 79.0 +- 26.9 of BRISK's
// 512, unrelated pairs in 125 and 236 (mild_analysis --measure-priors --features brisk).
struct SimilarityParams {
  int max_distance = 64;
  double sigma2 = 900.0;
  bool idf_weighting = true;
  bool vote_normalization = true;
  double burstiness_regularizer = 0.64;
  bool normalize_by_feature_counts = false;
  int early_termination_threshold = 20;

  static constexpr const char* kSection = "similarity";
  template <class Self, class Visit>
  static void declare(Self& p, Visit&& v) {
    v("max_distance", p.max_distance, Bounds::in(0, 256),
      "d0: phi(d) = exp(-d^2 / sigma2) for Hamming distance d <= max_distance, else 0. Per 256 bits: scaled by "
      "bits / 256 for wider descriptors (128 for BRISK). The original MILD values; 48 and 80 measured no better.");
    v("sigma2", p.sigma2, Bounds::above(0),
      "sigma^2 of phi, per 256 bits (scaled by the square of bits / 256); 400 and 1600 measured no better.");
    v("idf_weighting", p.idf_weighting, Bounds::any(),
      "Inter-image burstiness (seed paper III.D): weight each query feature's votes by log(N / N_f) ...");
    v("vote_normalization", p.vote_normalization, Bounds::any(),
      "... and divide them by the feature's total vote mass. Both on is the paper's phi'; both off costs 0.05 "
      "recall@100%P and 0.024 AP on average over the bench.");
    v("burstiness_regularizer", p.burstiness_regularizer, Bounds::atLeast(0),
      "Added to every feature's vote mass: 0.64 is phi of a match 20 bits away (sigma2 900), as the 2017 MILD "
      "code adds. Without it (0, the paper's formula) a query feature whose only matches are chance ones, far "
      "away, votes as much as one with a close match. On real frames, full of such features, each query's most "
      "similar keyframe alone scores recall@100%P / AP 0.02 / 0.38 on gp_day_a and 0.00 / 0.02 at night "
      "(gp_night_a) without it, 0.58 / 0.70 and 0.03 / 0.08 with it (docs/accuracy.md).");
    v("normalize_by_feature_counts", p.normalize_by_feature_counts, Bounds::any(),
      "Divide Phi' by |F_query| |F_keyframe| (the paper's Phi' without burstiness weighting).");
    v("early_termination_threshold", p.early_termination_threshold, Bounds::in(0, 64),
      "Early termination: reject a candidate whose distance on its first 64 bits exceeds this, without reading "
      "the rest. 64 never rejects; values >= max_distance never change a score. Unrelated pairs differ in about "
      "32 of the first 64 bits, pairs within d0 in about d/4, so 20 rejects nearly every outlier early; "
      "recall@100%P on the bench is unchanged.");
  }
  void validate() const { validateDeclared(*this); }
  // The parameters a database of `bits`-bit descriptors runs with (unchanged for 256).
  SimilarityParams scaledTo(int bits) const;
};

// phi(d) for every distance a supported descriptor can have (0..512), precomputed, with the
// parameters as given (scale them first).
class PhiTable {
 public:
  explicit PhiTable(const SimilarityParams& params);
  double operator()(int distance) const { return table_[distance]; }

 private:
  std::array<double, kMaxDescriptorBits + 1> table_{};
};

}  // namespace mild
