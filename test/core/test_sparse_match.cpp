#include <gtest/gtest.h>

#include <random>

#include <opencv2/imgcodecs.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"
#include "mild_lcd/verification/sparse_matcher.hpp"
#include "random_descriptors.hpp"

namespace mild {
namespace {

std::vector<FeatureMatch> bruteForceNearest(const DescriptorList& query, const DescriptorList& train,
                                            int max_distance) {
  std::vector<FeatureMatch> out;
  for (size_t q = 0; q < query.size(); ++q) {
    int best = -1, best_d = 1000;
    for (size_t t = 0; t < train.size(); ++t) {
      const int d = hammingDistance(query[q], train[t]);
      if (d < best_d) best_d = d, best = static_cast<int>(t);
    }
    if (best >= 0 && best_d <= max_distance) out.push_back({static_cast<int>(q), best, best_d});
  }
  return out;
}

TEST(SparseMatcher, FindsEveryNearestNeighbourCloserThanM) {
  std::mt19937_64 rng(3);
  for (int m : {16, 24, 32}) {
    const DescriptorList train = test::randomDescriptors(1200, rng);
    DescriptorList query;
    std::uniform_int_distribution<int> pick(0, 1199), bits(0, m - 1);
    for (int i = 0; i < 600; ++i) query.push_back(test::flipRandomBits(train[pick(rng)], bits(rng), rng));
    for (int i = 0; i < 300; ++i) query.push_back(test::randomDescriptor(rng));
    SparseMatchParams p;
    p.num_tables = m;
    p.max_distance = m - 1;  // pigeonhole: every pair closer than m meets in some table (r = 0)
    SparseMatcher matcher(p);
    EXPECT_EQ(matcher.match(query, train), bruteForceNearest(query, train, m - 1)) << "m=" << m;
    if (m <= 24) {  // 8-bit substrings (m = 32) have only 256 buckets: dense by construction
      EXPECT_LT(matcher.lastStats().candidates, query.size() * train.size() / 20) << "not sparse, m=" << m;
    }
  }
}

TEST(SparseMatcher, RatioTestNeedsAClearlyBetterNearestNeighbour) {
  std::mt19937_64 rng(5);
  const Descriptor q = test::randomDescriptor(rng);
  SparseMatchParams p;
  p.ratio = 0.8;
  SparseMatcher matcher(p);
  // Nearest 10 bits away, second 11: ambiguous, rejected.
  EXPECT_TRUE(matcher.match({q}, {test::flipRandomBits(q, 10, rng), test::flipRandomBits(q, 11, rng)}).empty());
  // Nearest 4, second 20: kept.
  const auto kept = matcher.match({q}, {test::flipRandomBits(q, 20, rng), test::flipRandomBits(q, 4, rng)});
  ASSERT_EQ(kept.size(), 1u);
  EXPECT_EQ(kept[0].train, 1);
  EXPECT_EQ(kept[0].distance, 4);
  // A lone candidate has no second best to be confused with.
  EXPECT_EQ(matcher.match({q}, {test::flipRandomBits(q, 6, rng)}).size(), 1u);
}

TEST(SparseMatcher, CrossCheckKeepsMutualNearestNeighboursOnly) {
  std::mt19937_64 rng(7);
  const Descriptor t = test::randomDescriptor(rng);
  const DescriptorList query = {test::flipRandomBits(t, 8, rng), test::flipRandomBits(t, 3, rng)};
  SparseMatchParams p;
  SparseMatcher plain(p);
  EXPECT_EQ(plain.match(query, {t}).size(), 2u);
  p.cross_check = true;
  SparseMatcher mutual(p);
  const auto m = mutual.match(query, {t});
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0].query, 1);
}

TEST(SparseMatcher, MaxDistanceDropsFarMatches) {
  std::mt19937_64 rng(9);
  const Descriptor t = test::randomDescriptor(rng);
  SparseMatchParams p;
  p.max_distance = 5;
  SparseMatcher matcher(p);
  EXPECT_EQ(matcher.match({test::flipRandomBits(t, 5, rng)}, {t}).size(), 1u);
  EXPECT_TRUE(matcher.match({test::flipRandomBits(t, 6, rng)}, {t}).empty());
}

TEST(SparseMatcher, KeypointGatingIgnoresFarAwayCandidates) {
  std::mt19937_64 rng(11);
  const Descriptor t = test::randomDescriptor(rng);
  const DescriptorList train = {t, test::flipRandomBits(t, 6, rng)};
  const DescriptorList query = {test::flipRandomBits(t, 1, rng)};
  const std::vector<cv::KeyPoint> qk = {cv::KeyPoint(100, 100, 31)};
  const std::vector<cv::KeyPoint> tk = {cv::KeyPoint(300, 50, 31), cv::KeyPoint(104, 97, 31)};
  SparseMatchParams p;
  SparseMatcher ungated(p);
  EXPECT_EQ(ungated.match(query, train, &qk, &tk).at(0).train, 0);
  p.max_keypoint_distance = 10.0;
  SparseMatcher gated(p);
  EXPECT_EQ(gated.match(query, train, &qk, &tk).at(0).train, 1);
  const std::vector<cv::KeyPoint> wrong_count = {cv::KeyPoint(1, 1, 31)};
  EXPECT_THROW(gated.match(query, train, &qk, &wrong_count), InvalidInput);
}

TEST(SparseMatcher, EmptyAndOneSidedInputsGiveNoMatches) {
  std::mt19937_64 rng(13);
  SparseMatcher matcher;
  const DescriptorList some = test::randomDescriptors(10, rng);
  EXPECT_TRUE(matcher.match(DescriptorList{}, DescriptorList{}).empty());
  EXPECT_TRUE(matcher.match(some, DescriptorList{}).empty());
  EXPECT_TRUE(matcher.match(DescriptorList{}, some).empty());
  EXPECT_TRUE(matcher.match(cv::Mat(), cv::Mat()).empty());
}

TEST(SparseMatcher, RejectsDescriptorsOfTheWrongWidth) {
  SparseMatcher matcher;
  const cv::Mat ok(5, 32, CV_8UC1, cv::Scalar(3));
  const cv::Mat brisk(5, 64, CV_8UC1, cv::Scalar(3));
  const cv::Mat sift(5, 128, CV_32FC1, cv::Scalar(3));
  EXPECT_THROW(matcher.match(ok, brisk), InvalidInput);
  EXPECT_THROW(matcher.match(sift, ok), InvalidInput);
  try {
    matcher.match(brisk, ok);
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("32"), std::string::npos);
  }
}

TEST(SparseMatcher, ReusedBuffersNeverLeakIntoTheNextPair) {
  std::mt19937_64 rng(15);
  const DescriptorList big = test::randomDescriptors(1500, rng);
  const DescriptorList small = test::randomDescriptors(40, rng);
  DescriptorList query;
  for (int i = 0; i < 40; ++i) query.push_back(test::flipRandomBits(small[i], 5, rng));
  for (int i = 0; i < 40; ++i) query.push_back(test::flipRandomBits(big[i], 5, rng));
  SparseMatcher reused, fresh;
  reused.match(query, big);
  EXPECT_EQ(reused.match(query, small), fresh.match(query, small));
  for (const auto& m : reused.match(query, small)) EXPECT_LT(m.train, 40);
}

TEST(SparseMatcher, RejectsInvalidParameters) {
  SparseMatchParams p;
  p.num_tables = 8;  // 32-bit substrings of ORB: no directly addressed table
  EXPECT_THROW(p.validateFor(256), InvalidInput);
  std::mt19937_64 rng(3);
  const DescriptorList orb = test::randomDescriptors(10, rng);
  SparseMatcher eight(p);
  EXPECT_THROW(eight.match(orb, orb), InvalidInput);
  p.num_tables = 22;  // fine for ORB, 24-bit substrings of BRISK
  EXPECT_NO_THROW(p.validateFor(256));
  EXPECT_THROW(p.validateFor(512), InvalidInput);
  p.num_tables = 65;
  EXPECT_THROW(SparseMatcher{p}, InvalidInput);
  p = SparseMatchParams{};
  p.ratio = 1.5;
  EXPECT_THROW(SparseMatcher{p}, InvalidInput);
  p = SparseMatchParams{};
  p.radius = 3;
  EXPECT_THROW(SparseMatcher{p}, InvalidInput);
}

// BRISK-width (512-bit) descriptors: the automatic table count keeps 12-bit substrings (43 tables),
// and matching finds the same pairs as brute force on near copies. Two widths in one pair are refused.
TEST(SparseMatcher, MatchesWideDescriptorsAndRefusesMixedWidths) {
  std::mt19937_64 rng(17);
  const DescriptorList train = test::randomDescriptors(300, rng, 64);
  DescriptorList query;
  for (int i = 0; i < 300; ++i) query.push_back(test::flipRandomBits(train[(i * 7) % 300], 20, rng));
  SparseMatcher matcher;
  const std::vector<FeatureMatch> matches = matcher.match(query, train);
  ASSERT_EQ(matches.size(), 300u);  // 20 of 512 bits: every copy shares a 12-bit substring
  for (const FeatureMatch& m : matches) {
    EXPECT_EQ(m.train, (m.query * 7) % 300);
    EXPECT_EQ(m.distance, 20);
  }
  // The same matcher goes back to ORB's width, and refuses a pair of two widths.
  const DescriptorList orb = test::randomDescriptors(50, rng);
  EXPECT_EQ(matcher.match(orb, orb).size(), 50u);
  EXPECT_THROW(matcher.match(orb, train), InvalidInput);
}

Features fixtureFeatures(int frame) {
  char name[64];
  std::snprintf(name, sizeof(name), "/test/data/corridor_stride5/images/%06d.jpg", frame);
  const cv::Mat image = cv::imread(std::string(MILD_SOURCE_DIR) + name, cv::IMREAD_GRAYSCALE);
  OrbParams orb;
  orb.num_features = 1200;
  return OrbExtractor(orb).extract(image);
}

TEST(GeometricVerifier, AcceptsATrueLoopPairAndRejectsUnrelatedViews) {
  const Features loop_query = fixtureFeatures(56), loop_match = fixtureFeatures(5);  // ground truth overlap 1.0
  const Features elsewhere = fixtureFeatures(30);                                    // not listed: overlap < 0.2
  GeometricVerifier fundamental{VerificationParams{}};
  const GeometricCheck loop = fundamental.check(loop_query, loop_match);
  EXPECT_TRUE(loop.verification.verified)
      << "inliers " << loop.verification.inliers << " of " << loop.verification.matches;
  EXPECT_EQ(loop.model.rows, 3);
  EXPECT_EQ(loop.inlier_mask.size(), loop.matches.size());
  const Verification unrelated = fundamental.verify(loop_query, elsewhere);
  EXPECT_FALSE(unrelated.verified) << "inliers " << unrelated.inliers << " of " << unrelated.matches;
  EXPECT_GT(loop.verification.inliers, 3 * unrelated.inliers);

  VerificationParams with_intrinsics;  // the bench camera: 320x240, f = 256 px
  with_intrinsics.fx = with_intrinsics.fy = 256.0;
  with_intrinsics.cx = 159.5;
  with_intrinsics.cy = 119.5;
  GeometricVerifier essential(with_intrinsics);
  EXPECT_TRUE(essential.verify(loop_query, loop_match).verified);
  EXPECT_FALSE(essential.verify(loop_query, elsewhere).verified);
}

TEST(GeometricVerifier, TooFewMatchesAreNotVerifiedAndBadIndicesAreRejected) {
  GeometricVerifier verifier{VerificationParams{}};
  const std::vector<cv::KeyPoint> kp(5, cv::KeyPoint(10, 10, 31));
  const GeometricCheck few = verifier.fit(kp, kp, {{0, 0, 1}, {1, 1, 1}, {2, 2, 1}});
  EXPECT_TRUE(few.verification.attempted);
  EXPECT_FALSE(few.verification.verified);
  EXPECT_TRUE(few.model.empty());
  std::vector<FeatureMatch> bad(10, FeatureMatch{0, 0, 1});
  bad[9] = {0, 7, 1};
  EXPECT_THROW(verifier.fit(kp, kp, bad), InvalidInput);
  // Degenerate geometry (every point the same) yields no model rather than an exception.
  const std::vector<FeatureMatch> same(10, FeatureMatch{0, 0, 1});
  EXPECT_FALSE(verifier.fit(kp, kp, same).verification.verified);
  Features mismatched;
  mismatched.keypoints.resize(2);
  EXPECT_THROW(verifier.check(mismatched, mismatched), InvalidInput);
}

TEST(GeometricVerifier, RejectsInvalidParameters) {
  VerificationParams p;
  p.min_inliers = 3;
  EXPECT_THROW(GeometricVerifier{p}, InvalidInput);
  p = VerificationParams{};
  p.fx = 200.0;  // fy missing
  EXPECT_THROW(GeometricVerifier{p}, InvalidInput);
  p = VerificationParams{};
  p.confidence = 1.0;
  EXPECT_THROW(GeometricVerifier{p}, InvalidInput);
}

}  // namespace
}  // namespace mild
