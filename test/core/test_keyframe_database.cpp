#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <map>
#include <random>
#include <set>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/place/keyframe_database.hpp"
#include "random_descriptors.hpp"

namespace mild {
namespace {

using Candidate = std::function<bool(const Descriptor& query, FeatureId stored)>;

// The similarity formula of SimilarityParams written out directly over an explicit candidate set,
// early termination included: a candidate more than early_termination_threshold bits away on its
// first 64 bits takes no part (in index mode; exact search has no early termination).
std::vector<double> referenceSimilarity(const KeyframeDatabase& db, const DescriptorList& query, KeyframeIndex n,
                                        const Candidate& is_candidate, bool early_termination = true) {
  const SimilarityParams& p = db.params().similarity;
  std::vector<double> sim(n, 0.0);
  for (const Descriptor& f : query) {
    std::vector<std::pair<KeyframeIndex, double>> votes;
    for (KeyframeIndex k = 0; k < n; ++k) {
      for (FeatureId id = db.firstFeature(k); id < db.firstFeature(k) + db.featureCount(k); ++id) {
        const Descriptor stored = db.descriptor(id);
        const int d = hammingDistance(f, stored);
        const bool early_out =
            early_termination && popcount64(f.words[0] ^ stored.words[0]) > p.early_termination_threshold;
        if (d <= p.max_distance && !early_out && is_candidate(f, id))
          votes.emplace_back(k, std::exp(-double(d) * d / p.sigma2));
      }
    }
    if (votes.empty()) continue;
    double mass = p.burstiness_regularizer;
    std::set<KeyframeIndex> hit;
    for (auto& [k, phi] : votes) {
      mass += phi;
      hit.insert(k);
    }
    const double w = (p.idf_weighting ? std::log(double(n) / hit.size()) : 1.0) / (p.vote_normalization ? mass : 1.0);
    for (auto& [k, phi] : votes) sim[k] += w * phi;
  }
  if (p.normalize_by_feature_counts) {
    for (KeyframeIndex k = 0; k < n; ++k) {
      if (db.featureCount(k) > 0) sim[k] /= double(query.size()) * db.featureCount(k);
    }
  }
  return sim;
}

void expectNear(const std::vector<double>& actual, const std::vector<double>& expected) {
  ASSERT_EQ(actual.size(), expected.size());
  for (size_t k = 0; k < actual.size(); ++k) {
    EXPECT_NEAR(actual[k], expected[k], 1e-9 * (1.0 + std::abs(expected[k]))) << "keyframe " << k;
  }
}

// Keyframes that share noisy copies of a common pool of "landmarks", so that queries get votes at
// every distance and from several keyframes.
struct Scene {
  DescriptorList landmarks;
  std::vector<DescriptorList> keyframes;
  DescriptorList query;
};

Scene makeScene(std::mt19937_64& rng, int keyframes = 12, int features = 60) {
  Scene s;
  s.landmarks = test::randomDescriptors(300, rng);
  std::uniform_int_distribution<int> landmark(0, 299), noise(0, 70);
  for (int k = 0; k < keyframes; ++k) {
    DescriptorList kf;
    for (int i = 0; i < features; ++i) kf.push_back(test::flipRandomBits(s.landmarks[landmark(rng)], noise(rng), rng));
    s.keyframes.push_back(kf);
  }
  for (int i = 0; i < 80; ++i) s.query.push_back(test::flipRandomBits(s.landmarks[landmark(rng)], noise(rng), rng));
  return s;
}

DatabaseParams paramsWith(int m, int r) {
  DatabaseParams p;
  p.index.num_tables = m;
  p.index.radius = r;
  p.index.cap_buckets = false;
  return p;
}

// A stored feature is an MIH candidate when it sits in a bucket of some table that the query
// probes: its substring is within r of the query's, and no earlier feature of its keyframe took
// that bucket (intra-image rule).
Candidate mihCandidates(const KeyframeDatabase& db) {
  return [&db](const Descriptor& q, FeatureId id) {
    const MihIndex& index = db.index();
    const KeyframeIndex k = db.keyframeOf(id);
    const Descriptor stored = db.descriptor(id);
    for (int t = 0; t < index.layout().count(); ++t) {
      if (!index.meetsInTable(q, stored, t)) continue;
      bool bucket_taken = false;
      for (FeatureId earlier = db.firstFeature(k); earlier < id; ++earlier) {
        bucket_taken |= index.layout().key(db.descriptor(earlier), t) == index.layout().key(stored, t);
      }
      if (!bucket_taken) return true;
    }
    return false;
  };
}

// The near-past policy on its own (near_past.hpp): walking back from the limit, the band goes on
// while the matched count stays within rise x sqrt(valley) of the valley (the fewest matched between
// the keyframe and the query, the exclusion window [limit, end) included), never below `floor`.
TEST(NearPastBand, FollowsTheViewContinuousWithThePresent) {
  // 100 keyframes stored, the exclusion window is 80..99. The view fades from 400 matched features
  // (the newest keyframe) to 100 at keyframe 60 and ends there: older keyframes match 0-2.
  std::vector<uint32_t> matched(100);
  for (size_t k = 0; k < matched.size(); ++k) matched[k] = k % 3;
  for (size_t k = 60; k < 100; ++k) matched[k] = static_cast<uint32_t>(100 + (k - 60) * 300 / 39);
  NearPastRule rule;
  EXPECT_EQ(nearPastBand(matched, 80, rule), 20u) << "80 down to 60: the fading view; then it ends at once";
  rule.floor = 70;
  EXPECT_EQ(nearPastBand(matched, 80, rule), 10u) << "never below the session's start";
  rule = NearPastRule{};
  // A revisit right at the limit: the window's valley (the view had faded to the chance level, 20,
  // by keyframe 82) separates it from the present.
  std::vector<uint32_t> revisit(100, 20);
  for (size_t k = 95; k < 100; ++k) revisit[k] = 300;  // the present
  for (size_t k = 76; k < 82; ++k) revisit[k] = 120;   // the place seen again, keyframes 76..81
  EXPECT_EQ(nearPastBand(revisit, 80, rule), 0u) << "the first eligible keyframe is a revisit, a candidate at once";
  std::vector<uint32_t> first(100, 20);
  for (size_t k = 95; k < 100; ++k) first[k] = 300;
  first[0] = 120;  // keyframe 0, the only eligible one, revisited
  EXPECT_EQ(nearPastBand(first, 1, rule), 0u) << "however few keyframes are eligible";
  // A window whose valley is within its own spread of zero: the present's view had ended there.
  std::vector<uint32_t> faded(100, 3);
  for (size_t k = 95; k < 100; ++k) faded[k] = 300;
  EXPECT_EQ(nearPastBand(faded, 80, rule), 0u) << "keyframes that show neither place are not the near past";
  // No exclusion window: the newest keyframe is the present's nearest neighbour.
  EXPECT_EQ(nearPastBand(matched, 100, rule), 40u);
  EXPECT_EQ(nearPastBand(matched, 0, rule), 0u);
}

TEST(KeyframeDatabase, IndexSimilarityEqualsTheFormulaOverTheCandidateSet) {
  for (auto [m, r] : std::vector<std::pair<int, int>>{{16, 0}, {8, 1}, {12, 2}, {32, 0}}) {
    for (bool burstiness : {true, false}) {
      std::mt19937_64 rng(100 + m + r);
      DatabaseParams p = paramsWith(m, r);
      p.similarity.idf_weighting = burstiness;
      p.similarity.vote_normalization = burstiness;
      p.similarity.normalize_by_feature_counts = !burstiness;
      p.similarity.burstiness_regularizer = burstiness ? 0.3 : 0.0;
      KeyframeDatabase db(p);
      const Scene s = makeScene(rng);
      for (const auto& kf : s.keyframes) db.insert(kf);
      const QueryResult result = db.query(s.query);
      ASSERT_GT(result.stats.votes, 0u);
      SCOPED_TRACE("m=" + std::to_string(m) + " r=" + std::to_string(r));
      expectNear(result.similarity, referenceSimilarity(db, s.query, db.size(), mihCandidates(db)));
    }
  }
}

TEST(KeyframeDatabase, ExactModeEqualsBruteForceOverAllFeatures) {
  std::mt19937_64 rng(9);
  KeyframeDatabase db(paramsWith(16, 0));
  const Scene s = makeScene(rng);
  for (const auto& kf : s.keyframes) db.insert(kf);
  const QueryResult exact = db.query(s.query, kAllKeyframes, SearchMode::kExact);
  expectNear(exact.similarity, referenceSimilarity(
                                   db, s.query, db.size(), [](const Descriptor&, FeatureId) { return true; }, false));
  EXPECT_EQ(exact.stats.full_distances, s.query.size() * db.featureCount());
  // The index approximates: it can only miss votes, and on this scene it does.
  const QueryResult approx = db.query(s.query);
  EXPECT_LT(approx.stats.votes, exact.stats.votes);
}

TEST(KeyframeDatabase, CandidateLimitExcludesLaterKeyframesEntirely) {
  std::mt19937_64 rng(11);
  KeyframeDatabase db(paramsWith(16, 0));
  const Scene s = makeScene(rng);
  for (const auto& kf : s.keyframes) db.insert(kf);
  const QueryResult limited = db.query(s.query, 5);
  ASSERT_EQ(limited.similarity.size(), 5u);
  expectNear(limited.similarity, referenceSimilarity(db, s.query, 5, mihCandidates(db)));
}

TEST(KeyframeDatabase, RepeatedFeaturesInOneKeyframeDoNotOutvoteDistinctMatches) {
  std::mt19937_64 rng(21);
  DatabaseParams p;  // defaults: burstiness handling on, caps on
  KeyframeDatabase db(p);
  const Descriptor repeated = test::randomDescriptor(rng);
  const DescriptorList shared = test::randomDescriptors(50, rng);
  for (int k = 0; k < 6; ++k) db.insert(test::randomDescriptors(100, rng));  // unrelated keyframes
  const KeyframeIndex bursty = db.insert(DescriptorList(200, repeated));
  DescriptorList near_duplicates;
  for (const auto& d : shared) near_duplicates.push_back(test::flipRandomBits(d, 4, rng));
  near_duplicates.resize(200, test::randomDescriptor(rng));
  const KeyframeIndex distinct = db.insert(near_duplicates);

  DescriptorList query = shared;
  query.push_back(test::flipRandomBits(repeated, 2, rng));
  const QueryResult result = db.query(query);
  EXPECT_GT(result.similarity[distinct], result.similarity[bursty]);
  EXPECT_GT(result.similarity[bursty], 0.0);
}

TEST(KeyframeDatabase, FeatureSeenInEveryKeyframeContributesNothing) {
  std::mt19937_64 rng(31);
  KeyframeDatabase db(paramsWith(16, 0));
  const Descriptor everywhere = test::randomDescriptor(rng);
  for (int k = 0; k < 10; ++k) {
    DescriptorList kf = test::randomDescriptors(30, rng);
    kf.push_back(test::flipRandomBits(everywhere, 3, rng));
    db.insert(kf);
  }
  const QueryResult result = db.query({everywhere});
  EXPECT_EQ(result.stats.votes, 10u);
  for (double s : result.similarity) EXPECT_EQ(s, 0.0);
  // The same feature in only some keyframes does vote.
  KeyframeDatabase sparse(paramsWith(16, 0));
  sparse.insert({everywhere});
  sparse.insert(test::randomDescriptors(30, rng));
  EXPECT_GT(sparse.query({everywhere}).similarity[0], 0.0);
}

TEST(KeyframeDatabase, EarlyTerminationAtOrAboveD0IsBitIdentical) {
  std::mt19937_64 rng(41);
  const Scene s = makeScene(rng, 20, 80);
  DatabaseParams p = paramsWith(16, 1);
  // d0 = 32 so that a fair share of random candidates exceed it on the first 64 bits alone.
  p.similarity.max_distance = 32;
  p.similarity.early_termination_threshold = 32;
  KeyframeDatabase at_d0(p);
  p.similarity.early_termination_threshold = 64;
  KeyframeDatabase reference(p);
  p.similarity.early_termination_threshold = 20;
  KeyframeDatabase aggressive(p);
  for (const auto& kf : s.keyframes) {
    at_d0.insert(kf);
    reference.insert(kf);
    aggressive.insert(kf);
  }
  const QueryResult r_ref = reference.query(s.query);
  const QueryResult r_at = at_d0.query(s.query);
  EXPECT_EQ(r_at.similarity, r_ref.similarity);  // exact equality, not approximate
  EXPECT_GT(r_at.stats.early_rejections, 0u);
  EXPECT_LT(r_at.stats.full_distances, r_ref.stats.full_distances);
  EXPECT_EQ(r_ref.stats.early_rejections, 0u);

  const QueryResult r_aggr = aggressive.query(s.query);
  EXPECT_LT(r_aggr.stats.full_distances, r_at.stats.full_distances);
  EXPECT_EQ(r_aggr.stats.candidates_visited, r_ref.stats.candidates_visited);
  EXPECT_EQ(r_aggr.stats.full_distances + r_aggr.stats.early_rejections + r_aggr.stats.repeated_candidates,
            r_aggr.stats.candidates_visited);
  // r = 1 and copies within a few bits: close stored features are met in several tables, and
  // compared once.
  EXPECT_GT(r_aggr.stats.repeated_candidates, 0u);
}

// inline_prefixes changes where early termination reads the first 64 bits, nothing else: the same
// similarity bit for bit and the same work, through merges of recent entries and bounded buckets.
TEST(KeyframeDatabase, InlinePrefixesGiveIdenticalResults) {
  for (uint32_t bound : {0u, 6u}) {
    std::mt19937_64 rng(43);
    const Scene s = makeScene(rng, 200, 60);
    DatabaseParams p = paramsWith(16, bound == 0 ? 1 : 0);
    p.index.max_bucket_entries = bound;
    KeyframeDatabase reference(p);
    p.index.inline_prefixes = true;
    KeyframeDatabase inlined(p);
    for (size_t k = 0; k < s.keyframes.size(); ++k) {
      reference.insert(s.keyframes[k]);
      inlined.insert(s.keyframes[k]);
      if (k % 25 != 24) continue;
      const QueryResult a = reference.query(s.query), b = inlined.query(s.query);
      EXPECT_EQ(a.similarity, b.similarity) << "after keyframe " << k << ", bound " << bound;
      EXPECT_EQ(a.stats.candidates_visited, b.stats.candidates_visited);
      EXPECT_EQ(a.stats.early_rejections, b.stats.early_rejections);
      EXPECT_EQ(a.stats.repeated_candidates, b.stats.repeated_candidates);
      EXPECT_EQ(a.stats.full_distances, b.stats.full_distances);
    }
    // 12,000 entries per table: merged at least twice (a merge waits for 4,096 recent ones).
    if (bound > 0) {
      EXPECT_GT(inlined.index().evictedEntries(), 0u) << "the bound evicted nothing";
    }
    EXPECT_EQ(inlined.index().entryCount(), reference.index().entryCount());
    EXPECT_GT(inlined.memoryBytes(), reference.memoryBytes() + 4 * reference.index().entryCount())
        << "8 bytes per settled entry";
  }
}

// A query budget larger than every bucket changes nothing; a small one caps the entries each query
// feature reads, with or without inline prefixes, through merges and bounded buckets.
TEST(KeyframeDatabase, QueryBudgetCapsEntriesReadPerFeature) {
  for (bool inline_prefixes : {false, true}) {
    std::mt19937_64 rng(47);
    const Scene s = makeScene(rng, 200, 60);
    DatabaseParams p = paramsWith(16, 0);
    p.index.max_bucket_entries = 40;
    p.index.inline_prefixes = inline_prefixes;
    KeyframeDatabase reference(p);
    p.index.max_candidates_per_feature = 1u << 30;
    KeyframeDatabase ample(p);
    p.index.max_candidates_per_feature = 20;
    KeyframeDatabase tight(p);
    for (size_t k = 0; k < s.keyframes.size(); ++k) {
      reference.insert(s.keyframes[k]);
      ample.insert(s.keyframes[k]);
      tight.insert(s.keyframes[k]);
      if (k % 25 != 24) continue;
      const QueryResult a = reference.query(s.query), b = ample.query(s.query), c = tight.query(s.query);
      EXPECT_EQ(a.similarity, b.similarity) << "after keyframe " << k;
      EXPECT_EQ(a.stats.candidates_visited, b.stats.candidates_visited);
      EXPECT_LE(c.stats.candidates_visited, 20u * c.stats.query_features);
      EXPECT_LT(c.stats.candidates_visited, a.stats.candidates_visited) << "the budget of 20 never bit";
    }
  }
}

TEST(KeyframeDatabase, HoldsMoreThan65535KeyframesWithoutWrapAround) {
  std::mt19937_64 rng(51);
  DatabaseParams p;
  p.index.cap_buckets = false;
  KeyframeDatabase db(p);
  const KeyframeIndex n = 70000;
  std::vector<DescriptorList> probes;  // keep a few keyframes to query for
  const std::set<KeyframeIndex> probe_at = {3, 65535, 65536, 66000, n - 1};
  for (KeyframeIndex k = 0; k < n; ++k) {
    DescriptorList kf = test::randomDescriptors(10, rng);
    if (probe_at.count(k)) probes.push_back(kf);
    ASSERT_EQ(db.insert(kf), k);
  }
  ASSERT_EQ(db.size(), n);
  ASSERT_EQ(db.featureCount(), size_t{n} * 10);
  size_t i = 0;
  for (KeyframeIndex k : probe_at) {
    const QueryResult r = db.query(probes[i++]);
    ASSERT_EQ(r.similarity.size(), n);
    const auto best = std::max_element(r.similarity.begin(), r.similarity.end()) - r.similarity.begin();
    EXPECT_EQ(static_cast<KeyframeIndex>(best), k);
    EXPECT_EQ(db.keyframeOf(db.firstFeature(k)), k);
  }
}

// Votes find their keyframe through a table of 256-feature blocks: keyframes of every size,
// empty ones and ones spanning several blocks included, must own exactly their features.
TEST(KeyframeDatabase, KeyframeOfNamesTheOwnerOfEveryFeature) {
  std::mt19937_64 rng(52);
  KeyframeDatabase db{DatabaseParams{}};
  const std::vector<size_t> sizes = {0, 1, 255, 0, 0, 1, 256, 257, 3, 700, 0, 1, 1, 1, 600, 2, 513, 0};
  for (int round = 0; round < 2; ++round) {  // and again after clear()
    for (size_t n : sizes) db.insert(test::randomDescriptors(n, rng));
    for (KeyframeIndex k = 0; k < db.size(); ++k) {
      for (FeatureId f = db.firstFeature(k); f < db.firstFeature(k) + db.featureCount(k); ++f) {
        ASSERT_EQ(db.keyframeOf(f), k) << "feature " << f;
      }
    }
    db.clear();
  }
}

TEST(KeyframeDatabase, RejectsMalformedDescriptorsAndStaysUnchanged) {
  std::mt19937_64 rng(61);
  KeyframeDatabase db;
  db.insert(test::randomDescriptors(20, rng));
  const size_t features = db.featureCount();
  const size_t entries = db.index().entryCount();
  const cv::Mat too_narrow(10, 31, CV_8UC1, cv::Scalar(1));
  const cv::Mat too_wide(10, 64, CV_8UC1, cv::Scalar(1));
  const cv::Mat floats(10, 32, CV_32FC1, cv::Scalar(1));
  const cv::Mat two_channels(10, 32, CV_8UC2, cv::Scalar(1));
  for (const cv::Mat* bad : {&too_narrow, &too_wide, &floats, &two_channels}) {
    EXPECT_THROW(db.insert(*bad), InvalidInput);
    EXPECT_THROW(db.query(*bad), InvalidInput);
  }
  try {
    db.insert(too_narrow);
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("32"), std::string::npos) << e.what();
  }
  EXPECT_EQ(db.size(), 1u);
  EXPECT_EQ(db.featureCount(), features);
  EXPECT_EQ(db.index().entryCount(), entries);
  EXPECT_THROW(descriptorsFromBytes(nullptr, 33, 32), InvalidInput);
  const std::vector<uint8_t> bytes(64, 0);
  EXPECT_THROW(descriptorsFromBytes(bytes.data(), bytes.size(), 32, 3), InvalidInput);
  EXPECT_EQ(descriptorsFromBytes(bytes.data(), bytes.size(), 32, 2).size(), 2u);
  EXPECT_EQ(descriptorsFromBytes(bytes.data(), bytes.size(), 64, 1).size(), 1u);
  EXPECT_THROW(descriptorsFromBytes(bytes.data(), bytes.size(), 4), InvalidInput);  // not a supported width
  // A keyframe of another width than the database's is refused whole.
  EXPECT_THROW(db.insert(test::randomDescriptors(5, rng, 64)), InvalidInput);
  EXPECT_THROW(db.query(test::randomDescriptors(5, rng, 64)), InvalidInput);
  EXPECT_EQ(db.size(), 1u);
  EXPECT_EQ(db.featureCount(), features);
}

TEST(KeyframeDatabase, InsertAndQueryQueriesBeforeInserting) {
  std::mt19937_64 rng(71);
  KeyframeDatabase db(paramsWith(16, 0));
  const DescriptorList a = test::randomDescriptors(50, rng);
  EXPECT_TRUE(db.insertAndQuery(a).similarity.empty());
  db.insert(test::randomDescriptors(50, rng));
  const QueryResult r = db.insertAndQuery(a);
  ASSERT_EQ(r.similarity.size(), 2u);
  EXPECT_GT(r.similarity[0], r.similarity[1]);
  EXPECT_EQ(db.size(), 3u);
  EXPECT_EQ(db.descriptors(2), a);
  // Round trip through OpenCV's layout.
  EXPECT_EQ(descriptorsFromMat(descriptorsToMat(a)), a);
}

TEST(KeyframeDatabase, EmptyKeyframesAndEmptyQueriesAreFine) {
  std::mt19937_64 rng(81);
  KeyframeDatabase db;
  EXPECT_EQ(db.insert(DescriptorList{}), 0u);
  EXPECT_EQ(db.insert(cv::Mat()), 1u);
  db.insert(test::randomDescriptors(10, rng));
  const QueryResult r = db.query(DescriptorList{});
  EXPECT_EQ(r.similarity, std::vector<double>(3, 0.0));
}

TEST(KeyframeDatabase, ClearEmptiesEverything) {
  std::mt19937_64 rng(91);
  KeyframeDatabase db;
  db.insert(test::randomDescriptors(10, rng));
  db.clear();
  EXPECT_EQ(db.size(), 0u);
  EXPECT_EQ(db.featureCount(), 0u);
  EXPECT_EQ(db.index().entryCount(), 0u);
  EXPECT_EQ(db.insert(test::randomDescriptors(10, rng)), 0u);
}

}  // namespace
}  // namespace mild

namespace mild {
namespace {

// 300 keyframes of their own random features; `shared` of them (first .. first+count) also hold a
// noisy copy of part of the query's features, as keyframes that see the query's place do.
struct SharedView {
  KeyframeDatabase db;
  DescriptorList query;
};
SharedView sharedView(KeyframeIndex first, KeyframeIndex count) {
  std::mt19937_64 rng(42);
  SharedView v;
  v.query = test::randomDescriptors(200, rng);
  for (KeyframeIndex k = 0; k < 300; ++k) {
    DescriptorList features = test::randomDescriptors(200, rng);
    if (k >= first && k < first + count) {
      for (size_t i = 0; i < 80; ++i) features[i] = test::flipRandomBits(v.query[(i + k) % v.query.size()], 6, rng);
    }
    v.db.insert(features);
  }
  return v;
}

TEST(NearPast, KeyframesStillSharingTheViewUpToTheLimitAreLeftOut) {
  // Keyframes 255..299 see the query's place: the limit (the fixed exclusion) is 280, so 255..279
  // are the near past, contiguous with the present through the exclusion window.
  SharedView v = sharedView(255, 45);
  NearPastRule rule;
  const QueryResult r = v.db.query(v.query, 280, SearchMode::kIndex, &rule);
  EXPECT_EQ(r.near_past, 25u) << "the band reaches back to where the shared view began";
  EXPECT_EQ(r.similarity.size(), 255u);
  const QueryResult without = v.db.query(v.query, 280);
  EXPECT_EQ(without.near_past, 0u);
  EXPECT_EQ(std::max_element(without.similarity.begin(), without.similarity.end()) - without.similarity.begin() >= 255,
            true)
      << "without the rule, the near past is the best match";
}

TEST(NearPast, ARevisitSeparatedFromThePresentStaysACandidate) {
  // The same view at keyframes 100..124, far from the limit: a revisit, not the near past.
  SharedView v = sharedView(100, 25);
  NearPastRule rule;
  const QueryResult r = v.db.query(v.query, 280, SearchMode::kIndex, &rule);
  EXPECT_EQ(r.near_past, 0u);
  ASSERT_EQ(r.similarity.size(), 280u);
  const auto best = std::max_element(r.similarity.begin(), r.similarity.end()) - r.similarity.begin();
  EXPECT_GE(best, 100);
  EXPECT_LT(best, 125);
}

TEST(NearPast, ARevisitAtTheFirstEligibleKeyframeStaysACandidate) {
  // Keyframes 270..279 show the query's place and the exclusion window 280..299 does not: a revisit
  // that reaches the limit (a low keyframe rate), not the near past.
  SharedView v = sharedView(270, 10);
  NearPastRule rule;
  const QueryResult r = v.db.query(v.query, 280, SearchMode::kIndex, &rule);
  EXPECT_EQ(r.near_past, 0u);
  const auto best = std::max_element(r.similarity.begin(), r.similarity.end()) - r.similarity.begin();
  EXPECT_GE(best, 270);
}

TEST(NearPast, NeverReachesIntoAnEarlierSession) {
  SharedView v = sharedView(200, 100);  // everything from 200 on shares the view
  NearPastRule rule;
  rule.floor = 240;  // keyframes below 240 come from an earlier session
  const QueryResult r = v.db.query(v.query, 280, SearchMode::kIndex, &rule);
  EXPECT_EQ(r.near_past, 40u) << "the whole current session is the present";
  rule.floor = 279;  // one keyframe of this session eligible: no warm-up, the band is measured as ever
  EXPECT_EQ(v.db.query(v.query, 280, SearchMode::kIndex, &rule).near_past, 1u);
}

// Reading the exclusion window for the band leaves the eligible keyframes' votes as they were, with
// a query budget too (the window's ids are read besides it).
TEST(NearPast, TheWindowIsReadBesidesTheBudget) {
  SharedView v = sharedView(100, 25);
  NearPastRule rule;
  const QueryResult with = v.db.query(v.query, 280, SearchMode::kIndex, &rule);
  const QueryResult without = v.db.query(v.query, 280);
  ASSERT_EQ(with.near_past, 0u);
  EXPECT_EQ(with.similarity, without.similarity);
}

}  // namespace
}  // namespace mild
