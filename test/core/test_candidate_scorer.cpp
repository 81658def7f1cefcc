// The published loop probability (CandidateScorer): a logistic model of the filter's probability,
// the geometry's significance against chance and the candidate's saliency, given to every candidate
// whose verification was attempted; the verification gate (belowDecision) for those that failed it;
// and the decision, which alone carries the cost of a wrong loop.
#include <gtest/gtest.h>

#include <cmath>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/candidate_scorer.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/verification/chance_agreement.hpp"

namespace mild {
namespace {

CandidateScorer::Evidence ev(double filter_probability, double saliency, size_t eligible = 100) {
  return {filter_probability, saliency, eligible};
}

// A fundamental matrix with `inliers` of twice as many matches, on a 320 x 240 image (chance 1 %).
Verification checked(int inliers, bool verified, int matches = -1) {
  Verification v;
  v.attempted = true;
  v.verified = verified;
  v.matches = matches < 0 ? 2 * inliers : matches;
  v.inliers = inliers;
  v.inlier_ratio = v.matches > 0 ? static_cast<double>(inliers) / v.matches : 0.0;
  v.log10_false_alarms = log10FalseAlarms(v.matches, inliers, 0.0104, kFundamentalSample);
  return v;
}

TEST(CandidateScorer, IsTheLogisticOfItsFeatures) {
  ScoringParams params;
  params.weights = {0.5, 1.0, 0.25, -0.75};
  params.bias = -2.0;
  const CandidateScorer scorer(params);
  const std::vector<double> x = scorer.features(ev(0.2, 7.0), checked(40, true));
  ASSERT_EQ(x.size(), CandidateScorer::featureNames().size());
  ASSERT_EQ(x.size(), static_cast<size_t>(CandidateScorer::kFeatures));
  EXPECT_NEAR(x[0], std::log(0.2 / 0.8), 1e-12);
  EXPECT_NEAR(scorer.features(ev(1e-9, 7.0), checked(40, true))[0], -4.0, 1e-9) << "the filter's term is bounded";
  EXPECT_NEAR(scorer.features(ev(1.0, 7.0), checked(40, true))[0], 4.0, 1e-9);
  EXPECT_NEAR(x[1], std::log1p(-log10FalseAlarms(80, 40, 0.0104, 7)), 1e-12);
  EXPECT_NEAR(x[2], std::log(7.0), 1e-12);
  EXPECT_NEAR(scorer.probability(ev(0.2, 7.0), checked(40, true)),
              1.0 / (1.0 + std::exp(-(-2.0 + 0.5 * x[0] + x[1] + 0.25 * x[2] - 0.75 * x[3]))), 1e-12);
  EXPECT_EQ(x[3], 0.0) << "no other place verified";
  CandidateScorer::Evidence aliased = ev(0.2, 7.0);
  aliased.other_place_significance = 12.0;
  EXPECT_NEAR(scorer.features(aliased, checked(40, true))[3], std::log1p(12.0), 1e-12);
  EXPECT_LT(scorer.probability(aliased, checked(40, true)), scorer.probability(ev(0.2, 7.0), checked(40, true)))
      << "another place that verifies too lowers the probability";
  aliased.other_place_significance = std::nan("");
  EXPECT_EQ(scorer.features(aliased, checked(40, true))[3], 0.0);
  EXPECT_EQ(scorer.features(ev(0.2, -3.0), checked(40, true))[2], 0.0) << "a saliency below 1 counts as 1";
  EXPECT_EQ(scorer.features(ev(0.2, std::nan("")), checked(40, true))[2], 0.0);
  EXPECT_EQ(scorer.features(ev(0.2, 7.0), checked(7, false))[1], 0.0) << "what chance explains is no evidence";
}

TEST(CandidateScorer, GrowsWithEachOfItsEvidences) {
  const CandidateScorer scorer{ScoringParams{}};  // the fitted defaults
  EXPECT_LT(scorer.probability(ev(0.001, 5), checked(40, true)), scorer.probability(ev(0.1, 5), checked(40, true)));
  EXPECT_LT(scorer.probability(ev(0.1, 5), checked(20, true)), scorer.probability(ev(0.1, 5), checked(80, true)));
  EXPECT_LT(scorer.probability(ev(0.1, 2), checked(40, true)), scorer.probability(ev(0.1, 20), checked(40, true)));
  // The defaults mean what the README and docs/accuracy.md say: a strong verified revisit is a
  // loop; a candidate with the inliers chance gives a fundamental matrix (11-12 of 50 at the median),
  // an ordinary similarity and a weak filter is unlikely to be one.
  EXPECT_GT(scorer.probability(ev(0.9, 20), checked(150, true)), 0.9);
  EXPECT_LT(scorer.probability(ev(0.001, 2), checked(12, false, 50)), 0.05);
}

// What the filter's prior may do: add to a keyframe's own evidence, never replace it. A keyframe
// with strong similarity and many inliers outranks a neighbour the filter is sure of but whose
// evidence is nil (no inliers, an ordinary similarity).
TEST(CandidateScorer, StrongEvidenceOutranksAConfidentPriorWithout) {
  const CandidateScorer scorer{ScoringParams{}};
  EXPECT_GT(scorer.probability(ev(1e-6, 30), checked(150, true)), scorer.probability(ev(0.99, 0), checked(0, false)));
  EXPECT_LT(scorer.probability(ev(0.99, 0), checked(0, false)), ScoringParams{}.decision_probability)
      << "a prior alone is not a loop";
}

// With too few eligible keyframes to compare with, the filter and the saliency are undecided: the
// probability rests on the inliers (a loop at the first eligible keyframe is accepted on them).
TEST(CandidateScorer, TooFewKeyframesLeaveTheFilterAndTheSaliencyUndecided) {
  const CandidateScorer scorer{ScoringParams{}};
  const size_t few = static_cast<size_t>(ScoringParams{}.min_comparable_keyframes) - 1;
  EXPECT_EQ(scorer.probability(ev(0.001, 0.0, few), checked(140, true)),
            scorer.probability(ev(0.5, 1.0, 1000), checked(140, true)));
  EXPECT_GT(scorer.probability(ev(0.01, 0.0, 1), checked(140, true)), 0.5);
  EXPECT_LT(scorer.probability(ev(0.01, 0.0, 1), checked(12, false, 50)), 0.5) << "a weak geometry alone is not a loop";
  EXPECT_NE(scorer.probability(ev(0.001, 0.0, few + 1), checked(140, true)),
            scorer.probability(ev(0.5, 1.0, 1000), checked(140, true)));
}

TEST(CandidateScorer, ACandidateThatFailedVerificationKeepsALowProbability) {
  const CandidateScorer scorer{ScoringParams{}};
  const double failed = scorer.probability(ev(0.3, 3), checked(9, false));
  EXPECT_GT(failed, 0.0) << "it is ranked, not dropped";
  EXPECT_LT(failed, scorer.probability(ev(0.3, 3), checked(40, true)));
  EXPECT_EQ(scorer.probability(ev(0.3, 3), checked(0, false)), scorer.probability(ev(0.3, 3), checked(1, false)))
      << "no inliers is no evidence, as one is, not minus infinity";
}

// The gate: a candidate that failed verification is published with its own probability, below the
// decision, never accepted; below the decision the probability is left as it is (it is calibrated).
TEST(BelowDecision, IsItsOwnProbabilityCappedBelowTheDecision) {
  for (double decision : {0.05, 0.3, 0.5, 0.8, 0.909, 1.0}) {
    double last = -1.0;
    for (double p : {0.0, 1e-9, 0.2, 0.49, 0.5, 0.9, 0.999999, 1.0}) {
      const double gated = belowDecision(p, decision);
      EXPECT_LT(gated, decision) << p;
      EXPECT_GE(gated, 0.0);
      EXPECT_GE(gated, last) << "order kept";
      if (p < decision) {
        EXPECT_EQ(gated, p) << "a calibrated probability below the decision is published as it is";
      }
      last = gated;
    }
  }
}

// The cost of a wrong loop against a missed one moves the decision, never the probability.
TEST(Decision, IsTheCostRatioAndLeavesTheProbabilityAlone) {
  EXPECT_NEAR(decisionForCost(1.0), 0.5, 1e-12) << "even odds";
  EXPECT_NEAR(decisionForCost(10.0), 10.0 / 11.0, 1e-12);
  EXPECT_NEAR(ScoringParams{}.decision_probability, decisionForCost(10.0), 1e-3)
      << "the default: a wrong loop costs ten missed ones";
  EXPECT_LT(decisionForCost(4.0), decisionForCost(10.0));
  ScoringParams cautious, bold;
  cautious.decision_probability = decisionForCost(50.0);
  bold.decision_probability = decisionForCost(1.0);
  const CandidateScorer a(cautious), b(bold);
  for (int inliers : {9, 20, 40, 150}) {
    for (double filter : {0.01, 0.5, 0.95}) {
      EXPECT_EQ(a.probability(ev(filter, 6), checked(inliers, inliers >= 15)),
                b.probability(ev(filter, 6), checked(inliers, inliers >= 15)));
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
  params.weights = {0.669, 0.726, 0.778};  // the three-feature scorer of earlier versions
  EXPECT_THROW(CandidateScorer{params}, InvalidInput);
}

// Early stop bounds a candidate's probability with another place's significance as far as it is
// known; that bound holds only if more of it never raises the probability.
TEST(CandidateScorer, RefusesAnotherPlaceThatWouldRaiseTheProbability) {
  ScoringParams params;
  params.weights.at(3) = 0.1;
  try {
    CandidateScorer{params};
    FAIL() << "a positive weight on another place's significance was taken";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("scoring/weights[3]"), std::string::npos) << e.what();
  }
}

// Weights so large that two terms overflow to -inf and +inf made the probability NaN, which sorts
// candidates undefinedly and was published: they are refused, and the largest accepted ones give a
// probability on the most extreme evidence.
TEST(CandidateScorer, WeightsBeyondAnyFitAreRefusedAndTheLargestGiveAProbability) {
  ScoringParams params;
  params.weights = {1e308, 1e308, 0.0, 0.0};
  EXPECT_THROW(CandidateScorer{params}, InvalidInput);
  params.weights = {0.669, 0.726, 0.778, 0.0};
  params.bias = -1e308;
  EXPECT_THROW(CandidateScorer{params}, InvalidInput);
  params.weights = {1000, 1000, -1000, -1000};
  params.bias = -1000;
  const CandidateScorer scorer(params);
  Verification strongest = checked(100000, true, 100000);
  strongest.log10_false_alarms = -1e300;
  for (const auto& e : {ev(0.0, 1e300), ev(1.0, 0.0), ev(0.5, 1e300, 1000000)}) {
    for (const Verification& v : {strongest, checked(0, false), checked(100, true)}) {
      const double p = scorer.probability(e, v);
      EXPECT_TRUE(p >= 0.0 && p <= 1.0) << p;
    }
  }
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
