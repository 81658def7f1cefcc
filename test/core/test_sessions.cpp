// Sessions: a map saved and reloaded as a new session, and a saved map merged into a running one,
// against one uninterrupted run of the embedded sample (300 frames, loops from frame 40 on).

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "../common/scratch_folder.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/feature_front_end.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/detector/process_image.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "random_descriptors.hpp"
#include "test_images.hpp"

namespace fs = std::filesystem;

namespace mild {
namespace {

const std::string& kSample = test::kSampleDir;
constexpr int kFrames = 300;

const std::vector<cv::Mat>& frames() { return test::sampleFrames(); }

// Frames [first, last) with ids = frame numbers, stamps at 10 Hz; candidates appended as scored pairs.
void run(LoopDetector& d, int first, int last, std::vector<ScoredPair>& out,
         std::vector<DetectionResult>* results = nullptr) {
  for (int i = first; i < last; ++i) {
    DetectionResult r = processImage(d, frames()[i], PixelFormat::kGray, 0.1 * i, static_cast<uint64_t>(i));
    for (const LoopCandidate& c : r.candidates) out.push_back({i, static_cast<int>(c.id), c.probability});
    if (results) results->push_back(std::move(r));
  }
}

// The ground truth of queries from `first` on only, so that two runs are scored on the same queries.
Metrics scoreFrom(int first, const std::vector<ScoredPair>& pairs) {
  const GroundTruth all = loadGroundTruth(kSample + "/gt_loops.txt", kFrames);
  GroundTruth truth;
  for (const auto& p : all.right)
    if (p.first >= first) truth.right.insert(p);
  for (const auto& p : all.dont_care)
    if (p.first >= first) truth.dont_care.insert(p);
  for (int q : all.loop_queries)
    if (q >= first) truth.loop_queries.insert(q);
  std::vector<ScoredPair> scored;
  for (const ScoredPair& p : pairs)
    if (p.query >= first) scored.push_back(p);
  return evaluate(truth, scored, 40);
}

class Sessions : public mild::test::ScratchFolderTest {
 protected:
  // The uninterrupted run, once for all tests.
  static const std::vector<ScoredPair>& uninterrupted() {
    static const std::vector<ScoredPair> pairs = [] {
      LoopDetector d;
      std::vector<ScoredPair> out;
      run(d, 0, kFrames, out);
      return out;
    }();
    return pairs;
  }
};

TEST_F(Sessions, AMapReloadedAsANewSessionFindsTheSecondHalfsLoopsAsWellAsOneRun) {
  LoopDetector first;
  std::vector<ScoredPair> ignored, split;
  run(first, 0, 150, ignored);
  saveMap(first.map(), path("first_half.mild"));

  LoopDetector second;
  loadMap(second.map(), path("first_half.mild"), false);
  EXPECT_EQ(second.map().session(), 1u);
  std::vector<DetectionResult> results;
  run(second, 150, kFrames, split, &results);
  size_t across = 0;
  for (const DetectionResult& r : results) {
    EXPECT_EQ(r.query_session, 1u);
    for (const LoopCandidate& c : r.candidates) {
      EXPECT_EQ(c.session, c.id < 150 ? 0u : 1u) << "candidate " << c.id;
      across += c.session == 0 && c.accepted ? 1 : 0;
    }
  }
  EXPECT_GT(across, 10u) << "loops into yesterday's map";

  const Metrics one_run = scoreFrom(150, uninterrupted());
  const Metrics two_sessions = scoreFrom(150, split);
  ASSERT_GT(one_run.loop_queries, 50u);
  std::cout << "queries 150-299: one run R@100P " << one_run.recall_at_100_precision << " AP "
            << one_run.average_precision << "; two sessions R@100P " << two_sessions.recall_at_100_precision << " AP "
            << two_sessions.average_precision << "\n";
  // As well as one run: nothing lost by the reload (a new session may find more: its filter starts
  // afresh and yesterday's keyframes are exempt from the temporal exclusion).
  EXPECT_GE(two_sessions.recall_at_100_precision, one_run.recall_at_100_precision - 0.02)
      << "one run " << one_run.recall_at_100_precision << ", two sessions " << two_sessions.recall_at_100_precision;
  EXPECT_GE(two_sessions.average_precision, one_run.average_precision - 0.02);
}

TEST_F(Sessions, AMergedMapKeepsBothMapsAndItsLoopsAreFound) {
  LoopDetector yesterday;
  std::vector<ScoredPair> ignored, merged_run;
  run(yesterday, 0, 150, ignored);
  saveMap(yesterday.map(), path("yesterday.mild"));

  LoopDetector today;
  run(today, 150, 225, merged_run);
  const uint64_t next_id = today.map().nextId();
  const LoadReport report = mergeMap(today.map(), path("yesterday.mild"));
  EXPECT_NE(report.message.find("merged 150 keyframes"), std::string::npos) << report.message;
  ASSERT_EQ(today.map().size(), 225u);
  EXPECT_EQ(today.map().session(), 0u) << "the running session goes on";
  EXPECT_EQ(today.map().sessionStart(), 150u) << "the merged map comes before the running session";
  EXPECT_EQ(today.map().nextId(), next_id);
  for (uint64_t id : {0ull, 149ull}) EXPECT_EQ(today.map().record(*today.map().find(id)).session, 1u);
  for (uint64_t id : {150ull, 224ull}) EXPECT_EQ(today.map().record(*today.map().find(id)).session, 0u);

  std::vector<DetectionResult> results;
  run(today, 225, kFrames, merged_run, &results);
  size_t across = 0, within = 0;
  for (const DetectionResult& r : results) {
    for (const LoopCandidate& c : r.candidates) {
      if (!c.accepted) continue;
      (c.session == 1 ? across : within) += 1;
      EXPECT_EQ(c.session, c.id < 150 ? 1u : 0u);
    }
  }
  EXPECT_GT(across, 10u) << "loops into the merged map";
  // The running session's own keyframes stay candidates, under the temporal exclusion.
  for (const DetectionResult& r : results) {
    for (const LoopCandidate& c : r.candidates) {
      if (c.session == 0) {
        EXPECT_GE(r.query_id - c.id, 40u);
      }
    }
  }

  const Metrics one_run = scoreFrom(225, uninterrupted());
  const Metrics merged = scoreFrom(225, merged_run);
  ASSERT_GT(one_run.loop_queries, 30u);
  std::cout << "queries 225-299: one run R@100P " << one_run.recall_at_100_precision << " AP "
            << one_run.average_precision << "; merged R@100P " << merged.recall_at_100_precision << " AP "
            << merged.average_precision << "\n";
  EXPECT_NEAR(merged.recall_at_100_precision, one_run.recall_at_100_precision, 0.02)
      << "one run " << one_run.recall_at_100_precision << ", merged " << merged.recall_at_100_precision;

  // Every session is saved and comes back.
  saveMap(today.map(), path("both.mild"));
  const MapState state = readMapFile(path("both.mild"));
  ASSERT_EQ(state.records.size(), 300u);  // 150 merged, 150 of the running session
  EXPECT_EQ(state.records.front().session, 1u);
  EXPECT_EQ(state.records.back().session, 0u);
}

// The sample's features, extracted once: the stamp tests below replay them under other clocks.
const std::vector<Features>& sampleFeatures() {
  static const std::vector<Features> features = [] {
    const FeatureFrontEnd front_end(DetectorParams{}.features);
    std::vector<Features> out;
    for (const cv::Mat& frame : frames()) {
      out.push_back(front_end.extract(Observation::ofImage(frame, PixelFormat::kGray, 0.0)).features);
    }
    return out;
  }();
  return features;
}

// Query id -> candidate id of the candidates a run found within its own session.
using LoopsWithin = std::vector<std::pair<uint64_t, uint64_t>>;

// The sample (ids 0..299) stamped stamp(i), with detector/exclusion_seconds 1, on a detector
// `prepare` has given a map first (or not).
LoopsWithin loopsWithinTheRunningSession(const std::function<double(int)>& stamp,
                                         const std::function<void(LoopDetector&)>& prepare,
                                         std::vector<DetectionResult>* results = nullptr) {
  DetectorParams p;
  p.candidates.exclusion_seconds = 1.0;
  LoopDetector d(p);
  prepare(d);
  LoopsWithin loops;
  for (int i = 0; i < kFrames; ++i) {
    DetectionResult r = d.process(Observation::ofFeatures(sampleFeatures()[i], stamp(i), static_cast<uint64_t>(i)));
    for (const LoopCandidate& c : r.candidates) {
      if (c.session == r.query_session) loops.emplace_back(r.query_id, c.id);
    }
    if (results) results->push_back(std::move(r));
  }
  return loops;
}

// A map of another place: 300 keyframes of random features, ids from 10,000, stamped from `first`
// at 10 Hz.
void saveAnotherPlace(const std::string& file, double first) {
  DetectorParams p;
  p.verification.enabled = false;
  LoopDetector other(p);
  std::mt19937_64 rng(5);
  for (int k = 0; k < 300; ++k) {
    Features f;
    for (int i = 0; i < 200; ++i) {
      f.descriptors.push_back(test::randomDescriptor(rng));
      f.keypoints.emplace_back(1.0f * i, 1.0f * k, 7.0f);
    }
    other.process(Observation::ofFeatures(std::move(f), first + 0.1 * k, 10000 + static_cast<uint64_t>(k)));
  }
  saveMap(other.map(), file);
}

// Issue 49 item 3: the temporal exclusion compares stamps within the running session only. A stored
// session stamped later than the new run (a map recorded on wall time, the run on sim time) used to
// leave no candidate within the running session at all.
TEST_F(Sessions, AStoredSessionStampedLaterThanTheRunningOneHidesNoneOfItsLoops) {
  const auto sample_time = [](int i) { return 0.1 * i; };
  saveAnotherPlace(path("earlier.mild"), -2000.0);
  saveAnotherPlace(path("later.mild"), 2000.0);
  const LoopsWithin alone = loopsWithinTheRunningSession(sample_time, [](LoopDetector&) {});
  const LoopsWithin after_earlier = loopsWithinTheRunningSession(
      sample_time, [&](LoopDetector& d) { loadMap(d.map(), path("earlier.mild"), false); });
  const LoopsWithin after_later =
      loopsWithinTheRunningSession(sample_time, [&](LoopDetector& d) { loadMap(d.map(), path("later.mild"), false); });
  const LoopsWithin merged_later =
      loopsWithinTheRunningSession(sample_time, [&](LoopDetector& d) { mergeMap(d.map(), path("later.mild")); });
  std::cout << "candidates within the running session: alone " << alone.size() << ", after a map stamped earlier "
            << after_earlier.size() << ", later " << after_later.size() << ", merged later " << merged_later.size()
            << "\n";
  ASSERT_GT(alone.size(), 300u);
  EXPECT_GT(after_earlier.size(), alone.size() * 9 / 10) << "another place's map takes few of the candidates";
  EXPECT_EQ(after_later, after_earlier) << "the stored session's stamps are never compared with the running one's";
  EXPECT_EQ(merged_later, after_earlier);
}

// A clock that steps back within the running session (a replay restarted, sim time reset): the
// detector is not blinded to what came before the step. The step counts as no time passing, so the
// results are those of a clock that went on (here the frame exclusion, 4 s at 10 Hz, is the stricter
// rule either way).
TEST_F(Sessions, AClockThatStepsBackKeepsEverythingBeforeTheStepEligible) {
  const auto steady = [](int i) { return 1000.0 + 0.1 * i; };
  const auto restarted = [](int i) { return i < 150 ? 1000.0 + 0.1 * i : 0.1 * (i - 150); };
  const auto nothing = [](LoopDetector&) {};
  std::vector<DetectionResult> results;
  const LoopsWithin went_on = loopsWithinTheRunningSession(steady, nothing);
  const LoopsWithin stepped_back = loopsWithinTheRunningSession(restarted, nothing, &results);
  size_t into_before_the_step = 0;
  for (const auto& [query, candidate] : stepped_back) into_before_the_step += query >= 150 && candidate < 150 ? 1 : 0;
  std::cout << "candidates: steady clock " << went_on.size() << ", stepped back " << stepped_back.size() << " ("
            << into_before_the_step << " from after the step into before it)\n";
  EXPECT_GT(into_before_the_step, 50u);
  EXPECT_EQ(stepped_back, went_on);
  for (size_t i = 0; i < results.size(); ++i) EXPECT_EQ(results[i].stats.clock_stepped_back, i == 150) << i;
}

TEST_F(Sessions, AMergeThatSharesAnIdIsRefusedAndChangesNothing) {
  LoopDetector other;
  std::vector<ScoredPair> ignored;
  run(other, 0, 20, ignored);
  saveMap(other.map(), path("other.mild"));
  LoopDetector running;
  run(running, 15, 60, ignored);  // ids 15..59: 15..19 are in both
  const size_t size = running.map().size();
  try {
    mergeMap(running.map(), path("other.mild"));
    FAIL() << "merged two maps that share ids";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("keyframe id 15 is in both maps"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("other.mild"), std::string::npos) << e.what();
  }
  EXPECT_EQ(running.map().size(), size);
  EXPECT_EQ(running.map().sessionStart(), 0u);
  EXPECT_EQ(processImage(running, frames()[60], PixelFormat::kGray, 6.0).query_id, 60u);
}

}  // namespace
}  // namespace mild
