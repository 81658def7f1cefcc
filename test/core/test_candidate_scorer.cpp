// The published loop probability (CandidateScorer): a logistic model of the filter's probability
// and the inlier count, given to every candidate whose verification was attempted.
#include <gtest/gtest.h>

#include <cmath>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/candidate_scorer.hpp"
#include "mild_lcd/detector/loop_detector.hpp"

namespace mild {
namespace {

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
  params.weights = {0.5, 1.0};
  params.bias = -2.0;
  const CandidateScorer scorer(params);
  const std::vector<double> x = CandidateScorer::features(0.2, checked(40, true));
  ASSERT_EQ(x.size(), CandidateScorer::featureNames().size());
  ASSERT_EQ(x.size(), static_cast<size_t>(CandidateScorer::kFeatures));
  EXPECT_NEAR(x[0], std::log(0.2 / 0.8), 1e-12);
  EXPECT_NEAR(x[1], std::log(40.0), 1e-12);
  EXPECT_NEAR(scorer.probability(0.2, checked(40, true)), 1.0 / (1.0 + std::exp(-(-2.0 + 0.5 * x[0] + x[1]))), 1e-12);
}

TEST(CandidateScorer, GrowsWithTheFilterProbabilityAndTheInliers) {
  const CandidateScorer scorer{ScoringParams{}};  // the fitted defaults
  EXPECT_LT(scorer.probability(0.001, checked(40, true)), scorer.probability(0.1, checked(40, true)));
  EXPECT_LT(scorer.probability(0.1, checked(20, true)), scorer.probability(0.1, checked(80, true)));
  // The defaults mean what the README and docs/accuracy.md say: a strong verified revisit is a loop; a candidate with
  // the inliers chance gives a fundamental matrix (11-12 at the median) and a weak filter is
  // unlikely to be one, though not impossible (real revisits that verification misses).
  EXPECT_GT(scorer.probability(0.5, checked(60, true)), 0.9);
  EXPECT_LT(scorer.probability(0.001, checked(12, false)), 0.2);
}

TEST(CandidateScorer, ACandidateThatFailedVerificationKeepsALowProbability) {
  const CandidateScorer scorer{ScoringParams{}};
  const double failed = scorer.probability(0.3, checked(9, false));
  EXPECT_GT(failed, 0.0) << "it is ranked, not dropped";
  EXPECT_LT(failed, scorer.probability(0.3, checked(40, true)));
  EXPECT_EQ(scorer.probability(0.3, checked(0, false)), scorer.probability(0.3, checked(1, false)))
      << "no inliers counts as one (ln 1 = 0), not as minus infinity";
}

TEST(CandidateScorer, OffGivesTheFilterProbability) {
  ScoringParams params;
  params.enabled = false;
  EXPECT_EQ(CandidateScorer(params).probability(0.37, checked(100, true)), 0.37);
}

TEST(CandidateScorer, RejectsAWeightVectorOfAnotherLength) {
  ScoringParams params;
  params.weights = {0.501, -0.334, 3.475, 5.264, 9.63};  // the five-feature scorer of earlier versions
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
