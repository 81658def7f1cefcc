// The hub correction (filter/keyframe_hubness.hpp, filter/hub_corrected_filter.hpp): a keyframe
// that resembles every query stops drawing the filter from the keyframe that resembles this place,
// a keyframe truly revisited by a long stretch of queries is not made a hub, and the correction's
// state survives a save and a load, bit for bit, or is refused whole.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "fixture_params.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/detector/process_image.hpp"
#include "mild_lcd/filter/filters.hpp"
#include "mild_lcd/filter/hub_corrected_filter.hpp"
#include "mild_lcd/filter/keyframe_hubness.hpp"
#include "test_images.hpp"

namespace mild {
namespace {

constexpr size_t kKeyframes = 200;
constexpr size_t kHub = 40;

// Query t's similarity to kKeyframes keyframes: noise, keyframe kHub a little above everything
// always (it resembles every place), and, when `place` is set, that keyframe well above the noise
// but below the hub.
std::vector<double> similarityAt(int t, int place = -1) {
  std::mt19937 rng(static_cast<unsigned>(t) + 7u);
  std::uniform_real_distribution<double> noise(0.0, 1.0);
  std::vector<double> s(kKeyframes);
  for (double& v : s) v = noise(rng);
  s[kHub] += 4.0;
  if (place >= 0) s[static_cast<size_t>(place)] += 3.0;
  return s;
}

FilterParams withHubness(int min_queries) {
  FilterParams p;
  p.hubness_min_queries = min_queries;
  return p;
}

size_t best(const std::vector<double>& v) {
  size_t b = 0;
  for (size_t j = 1; j < v.size(); ++j) {
    if (v[j] > v[b]) b = j;
  }
  return b;
}

TEST(KeyframeHubness, AKeyframeThatResemblesEverythingIsDiscounted) {
  KeyframeHubness hubness(10);
  for (int t = 0; t < 30; ++t) hubness.correct(similarityAt(t));
  EXPECT_GT(hubness.hubness(kHub), 5.0) << "its median saliency over 30 queries";
  EXPECT_LT(std::abs(hubness.hubness(kHub + 1)), 1.0) << "an ordinary keyframe";
  const std::vector<double> corrected = hubness.correct(similarityAt(30, 120));
  EXPECT_EQ(best(corrected), 120u) << "the place itself, not the hub";
  EXPECT_EQ(best(similarityAt(30, 120)), kHub) << "what the similarity alone would choose";
}

TEST(KeyframeHubness, NothingIsCorrectedBeforeEnoughQueries) {
  KeyframeHubness hubness(10);
  for (int t = 0; t < 9; ++t) hubness.correct(similarityAt(t));
  EXPECT_EQ(hubness.hubness(kHub), 0.0);
  const std::vector<double> s = similarityAt(9, 120);
  const std::vector<double> corrected = hubness.correct(s);
  const std::vector<double> z = robustSaliency(s);
  for (size_t j = 0; j < s.size(); ++j) EXPECT_DOUBLE_EQ(corrected[j], z[j]) << j;
}

TEST(KeyframeHubness, AStretchOfTrueRevisitsDoesNotMakeAHub) {
  // A corridor walked again: keyframe 120 is the place of 20 queries in a row, out of 60.
  KeyframeHubness hubness(10);
  for (int t = 0; t < 60; ++t) hubness.correct(similarityAt(t, t >= 20 && t < 40 ? 120 : -1));
  EXPECT_LT(hubness.hubness(120), 1.0) << "the median of its saliencies is that of an ordinary keyframe";
  EXPECT_GT(hubness.hubness(kHub), 5.0);
}

TEST(KeyframeHubness, ACutDatabaseForgetsTheKeyframesBeyondIt) {
  KeyframeHubness hubness(1);
  for (int t = 0; t < 5; ++t) hubness.correct(similarityAt(t));
  hubness.correct(std::vector<double>(30, 1.0));
  EXPECT_EQ(hubness.keyframes(), 30u);
  EXPECT_EQ(hubness.hubness(100), 0.0);
}

TEST(HubCorrectedFilter, OffIsTheFilterItself) {
  std::unique_ptr<TemporalFilter> plain = makeTemporalFilter(FilterParams{});
  EXPECT_EQ(plain->evidence(), nullptr);
  EXPECT_STREQ(plain->name(), "exclusive_hypotheses");
  std::unique_ptr<TemporalFilter> corrected = makeTemporalFilter(withHubness(10));
  EXPECT_STREQ(corrected->name(), "exclusive_hypotheses+hubness");
  ASSERT_NE(corrected->evidence(), nullptr);
}

TEST(HubCorrectedFilter, TheFilterFollowsThePlaceNotTheHub) {
  std::unique_ptr<TemporalFilter> plain = makeTemporalFilter(FilterParams{});
  std::unique_ptr<TemporalFilter> corrected = makeTemporalFilter(withHubness(10));
  for (int t = 0; t < 40; ++t) {
    plain->update(similarityAt(t));
    corrected->update(similarityAt(t));
  }
  // A revisit of keyframes 120, 121, ... that the hub outshines in similarity.
  std::vector<double> p, c;
  for (int t = 40; t < 46; ++t) {
    p = plain->update(similarityAt(t, 120 + (t - 40)));
    c = corrected->update(similarityAt(t, 120 + (t - 40)));
  }
  EXPECT_NEAR(static_cast<double>(best(c)), 125.0, 3.0);
  EXPECT_GT(c[best(c)], p[best(c)]) << "the place is more probable than uncorrected";
  EXPECT_LT(c[kHub], p[kHub]) << "the hub is less probable than uncorrected";
  EXPECT_EQ(best(*corrected->evidence()), 125u);
}

TEST(HubCorrectedFilter, ASavedStateResumesExactly) {
  std::unique_ptr<TemporalFilter> a = makeTemporalFilter(withHubness(5));
  for (int t = 0; t < 20; ++t) a->update(similarityAt(t, t % 7 == 0 ? 150 : -1));
  std::unique_ptr<TemporalFilter> b = makeTemporalFilter(withHubness(5));
  b->loadState(a->saveState());
  EXPECT_EQ(b->saveState(), a->saveState());
  for (int t = 20; t < 30; ++t) {
    const std::vector<double> s = similarityAt(t, 150);
    EXPECT_EQ(a->update(s), b->update(s)) << t;
    EXPECT_EQ(*a->evidence(), *b->evidence()) << t;
  }
}

TEST(HubCorrectedFilter, ABadStateIsRefusedAndChangesNothing) {
  std::unique_ptr<TemporalFilter> a = makeTemporalFilter(withHubness(5));
  for (int t = 0; t < 10; ++t) a->update(similarityAt(t));
  const std::vector<uint8_t> good = a->saveState();
  std::unique_ptr<TemporalFilter> plain = makeTemporalFilter(FilterParams{});
  plain->update(similarityAt(0));
  const std::vector<uint8_t> plain_state = plain->saveState();
  EXPECT_THROW(plain->loadState(good), InvalidInput) << "a plain filter does not take a corrected state";
  EXPECT_EQ(plain->saveState(), plain_state);
  for (const std::vector<uint8_t>& bad : {std::vector<uint8_t>{}, std::vector<uint8_t>(good.begin(), good.end() - 1),
                                          plain_state, std::vector<uint8_t>(good.begin(), good.begin() + 8)}) {
    EXPECT_THROW(a->loadState(bad), InvalidInput) << bad.size() << " bytes";
    EXPECT_EQ(a->saveState(), good) << bad.size() << " bytes";
  }
  std::vector<uint8_t> lying = good;
  lying[0] = 0xff;  // the wrapped filter's size, beyond the state
  EXPECT_THROW(a->loadState(lying), InvalidInput);
  EXPECT_EQ(a->saveState(), good);
}

TEST(HubCorrectedFilter, ItsStateCoversTheKeyframesEitherPartKnows) {
  // A map refuses a filter state covering more keyframes than it holds (KeyframeMap): a state whose
  // hubness alone is too long must count as too long.
  std::unique_ptr<TemporalFilter> a = makeTemporalFilter(withHubness(5));
  a->update(std::vector<double>(10, 1.0));
  EXPECT_EQ(a->stateKeyframes(), 10u);
  HubCorrectedFilter b(makeTemporalFilter(FilterParams{}), 5);
  std::vector<uint8_t> state(sizeof(uint64_t), 0);  // an empty wrapped state ...
  const std::vector<uint8_t> inner = makeTemporalFilter(FilterParams{})->saveState();
  const uint64_t size = inner.size();
  std::memcpy(state.data(), &size, sizeof size);
  state.insert(state.end(), inner.begin(), inner.end());
  KeyframeHubness long_hubness(5);
  long_hubness.correct(std::vector<double>(500, 1.0));  // ... beside the hubness of 500 keyframes
  long_hubness.appendState(state);
  b.loadState(state);
  EXPECT_EQ(b.stateKeyframes(), 500u);
}

TEST(HubCorrectedFilter, ResetForgetsTheHubs) {
  std::unique_ptr<TemporalFilter> a = makeTemporalFilter(withHubness(5));
  for (int t = 0; t < 10; ++t) a->update(similarityAt(t));
  a->reset();
  std::unique_ptr<TemporalFilter> fresh = makeTemporalFilter(withHubness(5));
  EXPECT_EQ(a->saveState(), fresh->saveState());
  EXPECT_EQ(a->update(similarityAt(3)), fresh->update(similarityAt(3)));
}

TEST(HubCorrectedFilter, TheMapsMemoryCountsTheFilterAndItsHubness) {
  // memory_bytes (mild_offline --stats, the nodelet's diagnostics) is the map's: the filter's state
  // is part of it, and the correction's histograms (KeyframeHubness::kBins counts per keyframe) too.
  std::unique_ptr<TemporalFilter> plain = makeTemporalFilter(FilterParams{});
  std::unique_ptr<TemporalFilter> corrected = makeTemporalFilter(withHubness(5));
  for (int t = 0; t < 10; ++t) {
    plain->update(similarityAt(t));
    corrected->update(similarityAt(t));
  }
  EXPECT_GE(plain->memoryBytes(), 3 * kKeyframes * sizeof(double)) << "posterior, prior, probability";
  EXPECT_GE(corrected->memoryBytes(), plain->memoryBytes() + kKeyframes * KeyframeHubness::kBins * sizeof(uint16_t));

  DetectorParams params = test::fixtureParams();
  LoopDetector without(params);
  params.filter.hubness_min_queries = 3;
  LoopDetector with(params);
  for (size_t i = 0; i < test::fixtureFrames().size(); ++i) {
    processImage(without, test::fixtureFrames()[i], PixelFormat::kGray, 0.5 * i);
    processImage(with, test::fixtureFrames()[i], PixelFormat::kGray, 0.5 * i);
  }
  const size_t filtered = with.map().filter().stateKeyframes();
  ASSERT_GT(filtered, 0u);
  EXPECT_GE(with.map().memoryBytes(),
            without.map().memoryBytes() + filtered * KeyframeHubness::kBins * sizeof(uint16_t));
  EXPECT_GE(without.map().memoryBytes(), without.map().database().memoryBytes() + without.map().filter().memoryBytes());
}

TEST(HubCorrectedFilter, TheDetectorDrawsCandidatesFromWhatTheFilterWeighed) {
  DetectorParams params = test::fixtureParams();
  params.filter.hubness_min_queries = 3;
  LoopDetector detector(params);
  size_t checked = 0;
  for (size_t i = 0; i < test::fixtureFrames().size(); ++i) {
    const DetectionResult r = processImage(detector, test::fixtureFrames()[i], PixelFormat::kGray, 0.5 * i);
    const std::vector<double>* evidence = detector.map().filter().evidence();
    ASSERT_NE(evidence, nullptr);
    if (r.similarity.empty()) continue;
    ASSERT_EQ(evidence->size(), r.similarity.size());
    const std::vector<double> saliency = robustSaliency(*evidence);
    for (const LoopCandidate& c : r.candidates) {
      EXPECT_EQ(c.similarity, r.similarity[c.index]) << "the published similarity is the similarity itself";
      EXPECT_DOUBLE_EQ(c.saliency, saliency[c.index]) << "the saliency is of the corrected evidence";
      ++checked;
    }
  }
  EXPECT_GT(checked, 20u);
}

}  // namespace
}  // namespace mild
