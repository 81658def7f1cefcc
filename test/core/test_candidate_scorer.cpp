// The published loop probability (CandidateScorer): a logistic model of the filter's probability,
// the inlier count and the candidate's saliency, given to every candidate whose verification was
// attempted; and the verification gate (belowDecision) for those that failed it.
#include <gtest/gtest.h>

#include <cmath>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/candidate_scorer.hpp"
#include "mild_lcd/detector/loop_detector.hpp"

namespace mild {
namespace {

CandidateScorer::Evidence ev(double filter_probability, double saliency, size_t eligible = 100) {
  return {filter_probability, saliency, eligible};
}

Verification checked(int inliers, bool verified) {
  Verification v;
  v.attempted = true;
  v.verified = verified;
  v.matches = 2 * inliers;
  v.inliers = inliers;
  v.inlier_ratio = 0.5;
  return v;
}

TEST(CandidateScorer, IsTheLogisticOfItsFeatures) {
  ScoringParams params;
  params.weights = {0.5, 1.0, 0.25};
  params.bias = -2.0;
  const CandidateScorer scorer(params);
  const std::vector<double> x = scorer.features(ev(0.2, 7.0), checked(40, true));
  ASSERT_EQ(x.size(), CandidateScorer::featureNames().size());
  ASSERT_EQ(x.size(), static_cast<size_t>(CandidateScorer::kFeatures));
  EXPECT_NEAR(x[0], std::log(0.2 / 0.8), 1e-12);
  EXPECT_NEAR(x[1], std::log(40.0), 1e-12);
  EXPECT_NEAR(x[2], std::log(7.0), 1e-12);
  EXPECT_NEAR(scorer.probability(ev(0.2, 7.0), checked(40, true)),
              1.0 / (1.0 + std::exp(-(-2.0 + 0.5 * x[0] + x[1] + 0.25 * x[2]))), 1e-12);
  EXPECT_EQ(scorer.features(ev(0.2, -3.0), checked(40, true))[2], 0.0) << "a saliency below 1 counts as 1";
  EXPECT_EQ(scorer.features(ev(0.2, std::nan("")), checked(40, true))[2], 0.0);
}

TEST(CandidateScorer, GrowsWithEachOfItsEvidences) {
  const CandidateScorer scorer{ScoringParams{}};  // the fitted defaults
  EXPECT_LT(scorer.probability(ev(0.001, 5), checked(40, true)), scorer.probability(ev(0.1, 5), checked(40, true)));
  EXPECT_LT(scorer.probability(ev(0.1, 5), checked(20, true)), scorer.probability(ev(0.1, 5), checked(80, true)));
  EXPECT_LT(scorer.probability(ev(0.1, 2), checked(40, true)), scorer.probability(ev(0.1, 20), checked(40, true)));
  // The defaults mean what the README and docs/accuracy.md say: a strong verified revisit is a
  // loop; a candidate with the inliers chance gives a fundamental matrix (11-12 at the median), an
  // ordinary similarity and a weak filter is unlikely to be one. The scorer was fitted with a wrong
  // loop counted ten times a missed one, so 0.5 asks for more than even odds: 60 inliers with a
  // filter undecided (0.5) are not yet enough.
  EXPECT_GT(scorer.probability(ev(0.9, 20), checked(150, true)), 0.9);
  EXPECT_LT(scorer.probability(ev(0.5, 10), checked(60, true)), 0.6);
  EXPECT_LT(scorer.probability(ev(0.001, 2), checked(12, false)), 0.05);
}

// What the filter's prior may do: add to a keyframe's own evidence, never replace it. A keyframe
// with strong similarity and many inliers outranks a neighbour the filter is sure of but whose
// evidence is nil (no inliers, an ordinary similarity).
TEST(CandidateScorer, StrongEvidenceOutranksAConfidentPriorWithout) {
  const CandidateScorer scorer{ScoringParams{}};
  EXPECT_GT(scorer.probability(ev(1e-6, 30), checked(150, true)), scorer.probability(ev(0.99, 0), checked(0, false)));
  EXPECT_LT(scorer.probability(ev(0.99, 0), checked(0, false)), 0.5) << "a prior alone is not a loop";
}

// With too few eligible keyframes to compare with, the filter and the saliency are undecided: the
// probability rests on the inliers (a loop at the first eligible keyframe is accepted on them).
TEST(CandidateScorer, TooFewKeyframesLeaveTheFilterAndTheSaliencyUndecided) {
  const CandidateScorer scorer{ScoringParams{}};
  const size_t few = static_cast<size_t>(ScoringParams{}.min_comparable_keyframes) - 1;
  EXPECT_EQ(scorer.probability(ev(0.001, 0.0, few), checked(140, true)),
            scorer.probability(ev(0.5, 1.0, 1000), checked(140, true)));
  EXPECT_GT(scorer.probability(ev(0.01, 0.0, 1), checked(140, true)), 0.5);
  EXPECT_LT(scorer.probability(ev(0.01, 0.0, 1), checked(25, true)), 0.5) << "a weak geometry alone is not a loop";
  EXPECT_NE(scorer.probability(ev(0.001, 0.0, few + 1), checked(140, true)),
            scorer.probability(ev(0.5, 1.0, 1000), checked(140, true)));
}

TEST(CandidateScorer, ACandidateThatFailedVerificationKeepsALowProbability) {
  const CandidateScorer scorer{ScoringParams{}};
  const double failed = scorer.probability(ev(0.3, 3), checked(9, false));
  EXPECT_GT(failed, 0.0) << "it is ranked, not dropped";
  EXPECT_LT(failed, scorer.probability(ev(0.3, 3), checked(40, true)));
  EXPECT_EQ(scorer.probability(ev(0.3, 3), checked(0, false)), scorer.probability(ev(0.3, 3), checked(1, false)))
      << "no inliers counts as one (ln 1 = 0), not as minus infinity";
}

// The gate: a candidate that failed verification is published below the decision probability and
// below 0.5, whatever its score, in the order of its score.
TEST(BelowDecision, IsBelowTheDecisionAndHalfAndKeepsTheOrder) {
  for (double decision : {0.05, 0.3, 0.5, 0.8, 1.0}) {
    double last = -1.0;
    for (double p : {0.0, 1e-9, 0.2, 0.49, 0.5, 0.9, 0.999999, 1.0}) {
      const double gated = belowDecision(p, decision);
      EXPECT_LT(gated, decision) << p;
      EXPECT_LT(gated, 0.5) << p;
      EXPECT_GE(gated, 0.0);
      EXPECT_GE(gated, last) << "order kept";
      if (p > 0.0 && p < 1.0) {
        EXPECT_GT(gated, last);
      }
      last = gated;
    }
  }
}

TEST(CandidateScorer, OffGivesTheFilterProbability) {
  ScoringParams params;
  params.enabled = false;
  EXPECT_EQ(CandidateScorer(params).probability(ev(0.37, 12), checked(100, true)), 0.37);
}

TEST(CandidateScorer, RejectsAWeightVectorOfAnotherLength) {
  ScoringParams params;
  params.weights = {0.513, 1.048};  // the two-feature scorer of earlier versions
  EXPECT_THROW(CandidateScorer{params}, InvalidInput);
}

// The scorer's weights belong to the filter they were fitted with: switching filter/type alone
// would publish miscalibrated probabilities, so the configuration is refused, naming both.
TEST(CandidateScorer, AScorerFittedForAnotherFilterIsRefused) {
  DetectorParams params;
  params.filter.type = "independent_binary";
  try {
    params.validate();
    FAIL() << "a scorer fitted for exclusive_hypotheses ran with independent_binary";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("scoring/filter_type"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("independent_binary"), std::string::npos) << e.what();
  }
  params.scoring.enabled = false;
  EXPECT_NO_THROW(params.validate()) << "the filter's own probability, published as it is";
  params.scoring.enabled = true;
  params.scoring.filter_type = "independent_binary";
  EXPECT_NO_THROW(params.validate()) << "weights declared as fitted for this filter";
}

}  // namespace
}  // namespace mild
