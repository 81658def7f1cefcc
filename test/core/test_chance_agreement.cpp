// The geometry's evidence against chance (chance_agreement.hpp) and what it is for: a candidate's
// published probability that means the same whatever the resolution and the feature budget the
// scene was described with.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "mild_lcd/detector/candidate_scorer.hpp"
#include "mild_lcd/features/orb_extractor.hpp"
#include "mild_lcd/verification/chance_agreement.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace mild {
namespace {

std::vector<cv::KeyPoint> grid(float width, float height) {
  std::vector<cv::KeyPoint> out;
  for (float x = 0; x <= width; x += width / 10)
    for (float y = 0; y <= height; y += height / 10) out.emplace_back(x, y, 7.f);
  return out;
}

TEST(ChanceAgreement, IsTheToleranceBandOverTheAreaTheKeypointsCover) {
  EXPECT_NEAR(chanceInlierProbability(grid(320, 240), 1.0), 2.0 * 400.0 / (320.0 * 240.0), 1e-9);
  EXPECT_NEAR(chanceInlierProbability(grid(640, 480), 1.0), chanceInlierProbability(grid(320, 240), 1.0) / 2, 1e-9)
      << "twice the side, half the chance at the same tolerance in pixels";
  EXPECT_NEAR(chanceInlierProbability(grid(320, 240), 2.0), 2 * chanceInlierProbability(grid(320, 240), 1.0), 1e-9);
  EXPECT_EQ(chanceInlierProbability({}, 1.0), 1.0) << "no keypoints: no evidence possible";
  EXPECT_EQ(chanceInlierProbability({cv::KeyPoint(5, 5, 7), cv::KeyPoint(5, 9, 7)}, 1.0), 1.0) << "a line, no area";
  EXPECT_EQ(chanceInlierProbability(grid(2, 2), 1.0), 1.0) << "at most 1";
  EXPECT_GE(chanceInlierProbability(grid(2000, 2000), 1.0), kLeastChanceInlierProbability);
}

TEST(ChanceAgreement, FalseAlarmsFallWithInliersAndRiseWithMatchesAndChance) {
  const double p = 0.0104;  // 320 x 240, 1 pixel
  EXPECT_EQ(log10FalseAlarms(200, 7, p, 7), 0.0) << "a minimal sample explains itself";
  EXPECT_GT(log10FalseAlarms(100, 12, p, 7), 0.0) << "the inliers chance gives a fundamental matrix: not meaningful";
  EXPECT_LT(log10FalseAlarms(100, 40, p, 7), -10.0) << "40 of 100 is not chance";
  EXPECT_LT(log10FalseAlarms(100, 40, p, 7), log10FalseAlarms(100, 30, p, 7));
  EXPECT_LT(log10FalseAlarms(100, 30, p, 7), log10FalseAlarms(1000, 30, p, 7)) << "30 of 1000 is less surprising";
  EXPECT_LT(log10FalseAlarms(100, 30, p / 2, 7), log10FalseAlarms(100, 30, p, 7)) << "a finer tolerance, more surprise";
  EXPECT_TRUE(std::isfinite(log10FalseAlarms(5000, 5000, 1e-9, 5)));
  EXPECT_EQ(log10FalseAlarms(50, 80, p, 7), log10FalseAlarms(50, 50, p, 7)) << "inliers beyond the matches are clamped";
}

Features sampleFrame(int frame, double scale, int budget) {
  char name[64];
  std::snprintf(name, sizeof(name), "/sample/corridor/images/%06d.jpg", frame);
  cv::Mat image = cv::imread(std::string(MILD_SOURCE_DIR) + name, cv::IMREAD_GRAYSCALE);
  EXPECT_FALSE(image.empty()) << name;
  if (scale != 1.0) cv::resize(image, image, cv::Size(), scale, scale, cv::INTER_AREA);
  OrbParams params;
  params.num_features = budget;
  return OrbExtractor(params).extract(image);
}

// The probability the default scorer gives the pair (query, candidate) described at `scale` with
// `budget` ORB features, the filter and the similarity's saliency held fixed.
double pairProbability(int query, int candidate, double scale, int budget) {
  const Verification v = GeometricVerifier(VerificationParams{})
                             .verify(sampleFrame(query, scale, budget), sampleFrame(candidate, scale, budget));
  CandidateScorer::Evidence e;
  e.filter_probability = 0.5;
  e.saliency = 6.0;
  e.eligible_keyframes = 100;
  return CandidateScorer(ScoringParams{}).probability(e, v);
}

// The same, for a candidate whose geometry is no evidence at all.
double withoutGeometry() {
  CandidateScorer::Evidence e;
  e.filter_probability = 0.5;
  e.saliency = 6.0;
  e.eligible_keyframes = 100;
  return CandidateScorer(ScoringParams{}).probability(e, Verification{});
}

// The inliers of a true revisit double with the feature budget and with the image's side; their
// significance against chance does too, but the scorer reads its logarithm, so the probability moves
// by at most kTolerance. A pair of two places stays unlikely at every scale and budget.
TEST(ScaleFreeEvidence, TheProbabilityOfACandidateHoldsAcrossResolutionsAndFeatureBudgets) {
  constexpr double kTolerance = 0.1;
  const double reference = pairProbability(280, 34, 1.0, 800);
  EXPECT_GT(reference, 0.5) << "a revisit of the sample (second lap)";
  for (double scale : {1.0, 2.0}) {
    for (int budget : {800, 1600}) {
      SCOPED_TRACE("scale " + std::to_string(scale) + ", budget " + std::to_string(budget));
      const double revisit = pairProbability(280, 34, scale, budget);
      EXPECT_NEAR(revisit, reference, kTolerance);
      std::printf("scale %.0f, %d features: revisit %.4f, elsewhere %.4f\n", scale, budget, revisit,
                  pairProbability(280, 150, scale, budget));
      EXPECT_EQ(pairProbability(280, 150, scale, budget), withoutGeometry())
          << "another place of the corridor: chance explains its inliers at every scale and budget";
    }
  }
}

}  // namespace
}  // namespace mild
