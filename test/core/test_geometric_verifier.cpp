#include <gtest/gtest.h>

#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/orb_extractor.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace {

using mild::Features;
using mild::GeometricVerifier;
using mild::Verification;
using mild::VerificationParams;

// OpenCV's thread count for one test, restored after it.
class OpenCvThreads {
 public:
  explicit OpenCvThreads(int n) : before_(cv::getNumThreads()) { cv::setNumThreads(n); }
  ~OpenCvThreads() { cv::setNumThreads(before_); }

 private:
  int before_;
};

Features sampleFrame(int frame) {
  char name[64];
  std::snprintf(name, sizeof(name), "/sample/corridor/images/%06d.jpg", frame);
  const cv::Mat image = cv::imread(std::string(MILD_SOURCE_DIR) + name, cv::IMREAD_GRAYSCALE);
  EXPECT_FALSE(image.empty()) << name;
  return mild::OrbExtractor().extract(image);
}

void expectSame(const Verification& a, const Verification& b, size_t candidate) {
  SCOPED_TRACE("candidate " + std::to_string(candidate));
  EXPECT_EQ(a.attempted, b.attempted);
  EXPECT_EQ(a.verified, b.verified);
  EXPECT_EQ(a.matches, b.matches);
  EXPECT_EQ(a.inliers, b.inliers);
  EXPECT_EQ(a.inlier_ratio, b.inlier_ratio);
  EXPECT_EQ(a.coverage, b.coverage);
  EXPECT_EQ(a.homography_share, b.homography_share);
  ASSERT_EQ(a.inlier_matches.size(), b.inlier_matches.size());
  for (size_t i = 0; i < a.inlier_matches.size(); ++i) {
    EXPECT_EQ(a.inlier_matches[i].query, b.inlier_matches[i].query);
    EXPECT_EQ(a.inlier_matches[i].train, b.inlier_matches[i].train);
    EXPECT_EQ(a.inlier_matches[i].distance, b.inlier_matches[i].distance);
  }
  EXPECT_EQ(a.inlier_query_points, b.inlier_query_points);
  EXPECT_EQ(a.inlier_candidate_points, b.inlier_candidate_points);
  EXPECT_EQ(a.pose.valid, b.pose.valid);
}

// A query of the sample's second lap against candidates that see its place (first lap, neighbours)
// and candidates that do not: both kinds of model fit, the quick and the one that runs long.
std::vector<Features> mixedCandidates() {
  std::vector<Features> candidates;
  for (int frame : {40, 210, 120, 208, 5, 212, 160}) candidates.push_back(sampleFrame(frame));
  return candidates;
}

TEST(GeometricVerifier, VerifyingAllCandidatesAtOnceGivesWhatOneByOneGives) {
  const OpenCvThreads threads(2);
  const Features query = sampleFrame(210 - 1);
  const std::vector<Features> candidates = mixedCandidates();
  VerificationParams params;
  params.fx = params.fy = 256.0;
  params.cx = 159.5;
  params.cy = 119.5;
  const GeometricVerifier reference(params);
  std::vector<Verification> one_by_one;
  for (const Features& c : candidates) one_by_one.push_back(reference.verify(query, c));
  size_t verified = 0;
  for (const Verification& v : one_by_one) verified += v.verified;
  ASSERT_GT(verified, 0u);
  ASSERT_LT(verified, candidates.size());

  params.parallel_candidates = true;
  const GeometricVerifier concurrent(params);
  // Repeated, so that candidates land on different threads in different orders.
  for (int round = 0; round < 4; ++round) {
    const std::vector<Verification> all = concurrent.verifyAll(query, candidates);
    ASSERT_EQ(all.size(), candidates.size());
    for (size_t i = 0; i < all.size(); ++i) expectSame(all[i], one_by_one[i], i);
  }
  params.parallel_candidates = false;
  const std::vector<Verification> serial = GeometricVerifier(params).verifyAll(query, candidates);
  for (size_t i = 0; i < serial.size(); ++i) expectSame(serial[i], one_by_one[i], i);
}

TEST(GeometricVerifier, OneBadCandidateAmongManyIsAClearErrorAndTheVerifierStaysUsable) {
  const OpenCvThreads threads(2);
  const Features query = sampleFrame(209);
  std::vector<Features> candidates = mixedCandidates();
  VerificationParams params;
  params.parallel_candidates = true;
  const GeometricVerifier verifier(params);
  const std::vector<Verification> before = verifier.verifyAll(query, candidates);
  candidates[3].keypoints.pop_back();  // one keypoint short of its descriptors
  EXPECT_THROW(verifier.verifyAll(query, candidates), mild::InvalidInput);
  candidates[3] = sampleFrame(208);
  const std::vector<Verification> after = verifier.verifyAll(query, candidates);
  ASSERT_EQ(after.size(), before.size());
  for (size_t i = 0; i < after.size(); ++i) expectSame(after[i], before[i], i);
}

TEST(GeometricVerifier, AFitTheCallerDeclinesIsSkippedAfterMatchingAndTheOthersAreUnchanged) {
  const Features query = sampleFrame(209);
  const std::vector<Features> candidates = mixedCandidates();
  const GeometricVerifier verifier{VerificationParams{}};
  const std::vector<Verification> every = verifier.verifyAll(query, candidates);
  std::vector<size_t> earlier_seen;
  const auto every_other = [&](size_t index, int matches, const std::vector<Verification>& earlier) {
    EXPECT_EQ(matches, every[index].matches) << "needs_fit sees the candidate's descriptor matches";
    earlier_seen.push_back(earlier.size());
    return index % 2 == 0;
  };
  const std::vector<Verification> some = verifier.verifyAll(query, candidates, every_other);
  ASSERT_EQ(some.size(), candidates.size());
  for (size_t i = 0; i < some.size(); ++i) {
    if (i % 2 == 0) {
      expectSame(some[i], every[i], i);
      EXPECT_FALSE(some[i].fit_skipped);
    } else {
      EXPECT_TRUE(some[i].fit_skipped);
      EXPECT_TRUE(some[i].attempted);
      EXPECT_FALSE(some[i].verified);
      EXPECT_EQ(some[i].inliers, 0);
      EXPECT_EQ(some[i].matches, every[i].matches);
    }
    EXPECT_EQ(earlier_seen[i], i) << "needs_fit is given the verifications before the candidate";
  }
}

TEST(GeometricVerifier, EveryRobustEstimatorVerifiesTheSameRevisitAndRejectsAnotherPlace) {
  const Features query = sampleFrame(209);
  const Features revisit = sampleFrame(208);  // the same place a moment earlier
  const Features elsewhere = sampleFrame(120);
  VerificationParams params;
  params.method = "magsac";
  const Verification reference = GeometricVerifier(params).verify(query, revisit);
  ASSERT_TRUE(reference.verified);
  ASSERT_FALSE(GeometricVerifier(params).verify(query, elsewhere).verified);
  for (const std::string& method : mild::robustMethods()) {
    SCOPED_TRACE(method);
    params.method = method;
    const GeometricVerifier verifier(params);
    const Verification v = verifier.verify(query, revisit);
    EXPECT_TRUE(v.verified);
    EXPECT_EQ(v.matches, reference.matches);  // the estimator changes the fit, not the matching
    EXPECT_FALSE(verifier.verify(query, elsewhere).verified);
  }
  params.method = "lmeds";
  EXPECT_THROW(GeometricVerifier{params}, mild::InvalidInput);
}

TEST(GeometricVerifier, TheLayoutOfInliersIsMeasuredForVerifiedCandidatesOnly) {
  const Features query = sampleFrame(209);
  const GeometricVerifier verifier{VerificationParams{}};
  const Verification loop = verifier.verify(query, sampleFrame(208));
  ASSERT_TRUE(loop.verified);
  EXPECT_GT(loop.coverage, 0.0);
  EXPECT_GT(loop.homography_share, 0.0);
  const Verification other = verifier.verify(query, sampleFrame(120));
  ASSERT_FALSE(other.verified);
  EXPECT_EQ(other.coverage, 0.0);
  EXPECT_EQ(other.homography_share, 0.0);
}

}  // namespace
