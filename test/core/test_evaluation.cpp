#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

#include <nlohmann/json.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/offline/evaluation.hpp"

namespace fs = std::filesystem;

namespace mild {
namespace {

const std::string kData = std::string(MILD_SOURCE_DIR) + "/test/data";

struct Case {
  std::string gt_dir;      // holds gt_loops.txt
  std::string candidates;  // CSV
  int min_gap;
  // What ../shared/bench/score.py printed for this case (kept so the test also runs without it).
  double recall_at_100, average_precision, max_f1;
  size_t loop_queries, scored_queries, true_positives, false_positives;
};

const std::vector<Case>& cases() {
  static const std::vector<Case> all = {
      {kData + "/eval", kData + "/eval/candidates.csv", 40, 0.3333, 0.7475, 0.8, 9, 12, 8, 3},
      {kData + "/eval", kData + "/eval/candidates.csv", 90, 0.8889, 0.8889, 0.9412, 9, 9, 8, 0},
      // Bench 1.1 ground truth (the fixture's gt_loops.txt, cut from pub_corridor's by make_sample.py).
      {kData + "/corridor_stride5", kData + "/eval/corridor_stride5_candidates.csv", 8, 0.8462, 0.8759, 0.9167, 13, 51,
       12, 34},
  };
  return all;
}

double round4(double v) { return std::round(v * 1e4) / 1e4; }

TEST(Evaluation, MatchesTheRefereesRecordedResults) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.candidates + " min_gap=" + std::to_string(c.min_gap));
    const Metrics m = evaluate(loadGroundTruth(c.gt_dir + "/gt_loops.txt"), loadCandidates(c.candidates), c.min_gap);
    EXPECT_EQ(round4(m.recall_at_100_precision), c.recall_at_100);
    EXPECT_EQ(round4(m.average_precision), c.average_precision);
    EXPECT_EQ(round4(m.max_f1), c.max_f1);
    EXPECT_EQ(m.loop_queries, c.loop_queries);
    EXPECT_EQ(m.scored_queries, c.scored_queries);
    EXPECT_EQ(m.true_positives, c.true_positives);
    EXPECT_EQ(m.false_positives, c.false_positives);
  }
}

// Runs the referee itself when it is available (CI has ../shared beside the repository).
TEST(Evaluation, AgreesWithScorePyToFourDecimals) {
  const std::string score_py = MILD_SCORE_PY;
  if (!fs::exists(score_py)) GTEST_SKIP() << "referee not found at " << score_py;
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.candidates + " min_gap=" + std::to_string(c.min_gap));
    const std::string command = "/usr/bin/python3 '" + score_py + "' '" + c.gt_dir + "' '" + c.candidates +
                                "' --min-gap " + std::to_string(c.min_gap) + " --json";
    std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(command.c_str(), "r"), pclose);
    ASSERT_TRUE(pipe);
    std::string output;
    char buffer[4096];
    while (fgets(buffer, sizeof(buffer), pipe.get())) output += buffer;
    const auto referee = nlohmann::json::parse(output.substr(output.rfind('{')));
    const Metrics m = evaluate(loadGroundTruth(c.gt_dir + "/gt_loops.txt"), loadCandidates(c.candidates), c.min_gap);
    EXPECT_EQ(round4(m.recall_at_100_precision), referee["recall_at_100_precision"].get<double>());
    EXPECT_EQ(round4(m.average_precision), referee["average_precision"].get<double>());
    EXPECT_EQ(round4(m.max_f1), referee["max_f1"].get<double>());
    EXPECT_EQ(m.true_positives, referee["true_positives"].get<size_t>());
    EXPECT_EQ(m.false_positives, referee["false_positives"].get<size_t>());
    EXPECT_EQ(m.scored_queries, referee["scored_queries"].get<size_t>());
  }
}

TEST(Evaluation, BestCandidatePerQueryKeepsTheFirstOfEqualScores) {
  const auto best = bestPerQuery({{110, 20, 0.2}, {110, 21, 0.2}, {111, 5, 0.1}, {111, 6, 0.3}, {112, 100, 0.9}}, 40);
  ASSERT_EQ(best.size(), 2u);
  EXPECT_EQ(best[0].candidate, 20);
  EXPECT_EQ(best[1].candidate, 6);
}

TEST(Evaluation, MalformedGroundTruthNamesFileAndLine) {
  const fs::path path = fs::temp_directory_path() / "mild_bad_gt.txt";
  std::ofstream(path) << "10 0 0.5 1\n11 x 0.5 1\n";
  try {
    loadGroundTruth(path.string());
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find(path.string() + ":2"), std::string::npos) << e.what();
  }
  std::ofstream(path) << "10 0 0.5 7\n";
  EXPECT_THROW(loadGroundTruth(path.string()), InvalidInput);
  EXPECT_THROW(loadGroundTruth("/nonexistent/gt_loops.txt"), InvalidInput);
  // Pairs that cannot be frames of the sequence, and a file without pairs, are errors too.
  for (const char* line : {"10 -1 0.5 1\n", "5 9 0.5 1\n", "7 7 0.5 0\n"}) {
    std::ofstream(path) << line;
    EXPECT_THROW(loadGroundTruth(path.string()), InvalidInput) << line;
  }
  std::ofstream(path) << "90 10 0.5 1\n";
  EXPECT_NO_THROW(loadGroundTruth(path.string(), 91));
  EXPECT_THROW(loadGroundTruth(path.string(), 90), InvalidInput) << "frame 90 of a 90-frame sequence";
  std::ofstream(path) << "# only a comment\n\n";
  EXPECT_THROW(loadGroundTruth(path.string()), InvalidInput);
  EXPECT_THROW(loadGroundTruth(fs::temp_directory_path().string()), InvalidInput) << "a folder";
  EXPECT_THROW(loadCandidates("/nonexistent/candidates.csv"), InvalidInput);
}

TEST(Evaluation, AScoreThatIsNotANumberIsRefusedNamingTheLine) {
  // A NaN never equals itself: it once stopped the ranking's walk from advancing (an endless loop
  // growing the curve until memory ran out).
  const fs::path path = fs::temp_directory_path() / "mild_nan_candidates.csv";
  for (const char* score : {"nan", "inf", "-inf"}) {
    std::ofstream(path) << "query,candidate,score\n100,1,0.5\n101,2," << score << "\n";
    try {
      loadCandidates(path.string());
      FAIL() << score;
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(path.string() + ":3"), std::string::npos) << e.what();
    }
  }
  // Given directly, the walk still ends, and every pair is counted once.
  GroundTruth truth;
  truth.right = {{100, 1}};
  truth.loop_queries = {100};
  const Metrics m = evaluate(truth, {{100, 1, std::nan("")}, {101, 2, std::nan("")}, {102, 3, 0.5}}, 40);
  EXPECT_EQ(m.scored_queries, 3u);
  EXPECT_EQ(m.true_positives + m.false_positives, 3u);
  EXPECT_LE(m.curve.size(), 3u);
}

TEST(Evaluation, FrameNumbersAtTheEndsOfTheirRangeDoNotOverflowTheGap) {
  const auto best = bestPerQuery({{2147483647, -1, 0.5}, {-2147483647 - 1, 1, 0.5}, {100, 10, 0.4}}, 40);
  ASSERT_EQ(best.size(), 2u);  // the first is 2^31 frames apart; the second is before its candidate
  EXPECT_EQ(best[0].query, 100);
  EXPECT_EQ(best[1].query, 2147483647);
}

TEST(Evaluation, ScoresSurviveTheCsvRoundTrip) {
  for (double s : {0.123456789012, 1e-9, 0.99999999, 1.0, 0.0}) {
    EXPECT_NEAR(std::stod(formatScore(s)), s, 1e-10 * std::max(1.0, s));
  }
  EXPECT_NE(formatScore(0.9999999991), formatScore(0.9999999981));
}

}  // namespace
}  // namespace mild
