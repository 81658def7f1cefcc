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
      "d0, the Hamming distance beyond which a match votes nothing (bits per 256, scaled for other widths; 0 to "
      "256).");
    v("sigma2", p.sigma2, Bounds::above(0),
      "sigma^2 of a match's vote phi(d) = exp(-d^2 / sigma2) (squared bits per 256, scaled for other widths; > 0).");
    v("idf_weighting", p.idf_weighting, Bounds::any(),
      "Whether each query feature's votes are weighted by log(N / N_f), the seed paper's inter-image burstiness "
      "(true or false).");
    v("vote_normalization", p.vote_normalization, Bounds::any(),
      "Whether each query feature's votes are divided by its total vote mass, the seed paper's phi' with "
      "idf_weighting (true or false).");
    v("burstiness_regularizer", p.burstiness_regularizer, Bounds::atLeast(0),
      "Added to every query feature's vote mass before its votes are divided by it, so that a feature whose only "
      "matches are far votes little (vote units, >= 0).");
    v("normalize_by_feature_counts", p.normalize_by_feature_counts, Bounds::any(),
      "Whether Phi' is divided by the product of the query's and the keyframe's feature counts (true or false).");
    v("early_termination_threshold", p.early_termination_threshold, Bounds::in(0, 64),
      "A stored feature whose distance on the first 64 bits exceeds this is rejected without reading the rest "
      "(bits, 0 to 64; 64 never rejects).");
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
