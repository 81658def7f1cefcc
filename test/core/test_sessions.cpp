// Sessions: a map saved and reloaded as a new session, and a saved map merged into a running one,
// against one uninterrupted run of the embedded sample (300 frames, loops from frame 40 on).

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "../common/scratch_folder.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/detector/process_image.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "mild_lcd/offline/evaluation.hpp"
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
