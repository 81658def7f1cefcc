// Runs the installed-style mild_offline binary the way a user would and checks its contract.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "../common/run_command.hpp"
#include "../common/scratch_folder.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kFixture = std::string(MILD_SOURCE_DIR) + "/test/data/corridor_stride5";
const std::string kFixtureConfig = std::string(MILD_SOURCE_DIR) + "/test/data/corridor_stride5.yaml";

using ProcessResult = mild::test::CommandResult;

ProcessResult mildOffline(const std::string& args) {
  return mild::test::runCommand(std::string(MILD_OFFLINE_BIN) + " " + args);
}

class MildOffline : public mild::test::ScratchFolderTest {
 protected:
};

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST_F(MildOffline, WritesCandidatesStatsPlotsAndScores) {
  const ProcessResult run =
      mildOffline("--images " + kFixture + " --config " + kFixtureConfig + " --output " + path("c.csv") + " --gt " +
                  kFixture + "/gt_loops.txt --min-gap 8 --stats " + path("s.json") + " --plots " + path("plots"));
  ASSERT_EQ(run.status, 0) << run.output;
  EXPECT_NE(run.output.find("recall@100%P: "), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("average precision: "), std::string::npos);
  EXPECT_NE(run.output.find("max F1: "), std::string::npos);

  const std::string csv = readFile(path("c.csv"));
  EXPECT_EQ(csv.rfind("query,candidate,score\n", 0), 0u);
  EXPECT_GT(std::count(csv.begin(), csv.end(), '\n'), 20);

  const auto stats = nlohmann::json::parse(readFile(path("s.json")));
  for (const char* stage : {"extract_ms", "query_ms", "filter_ms", "verify_ms", "keyframe_ms"}) {
    for (const char* key : {"mean", "median", "p95", "p99", "max"}) {
      EXPECT_TRUE(stats[stage].contains(key)) << stage << "." << key;
    }
    EXPECT_GE(stats[stage]["max"].get<double>(), stats[stage]["median"].get<double>());
  }
  // keyframe_ms is the four stages' sum per keyframe, so its mean is the sum of their means.
  double stage_means = 0.0;
  for (const char* stage : {"extract_ms", "query_ms", "filter_ms", "verify_ms"})
    stage_means += stats[stage]["mean"].get<double>();
  EXPECT_NEAR(stats["keyframe_ms"]["mean"].get<double>(), stage_means, 1e-6 * stage_means);
  EXPECT_EQ(stats["keyframes"].get<int>(), 60);
  EXPECT_GT(stats["features"].get<int>(), 1000);
  EXPECT_GT(stats["memory_bytes"].get<int>(), 0);
  // The thread's CPU time per keyframe, and per window of 1,000 keyframes (one here: 60 keyframes).
  EXPECT_GT(stats["keyframe_cpu_ms"]["median"].get<double>(), 0.0);
  ASSERT_EQ(stats["windows"].size(), 1u);
  EXPECT_EQ(stats["windows"][0]["first"].get<int>(), 0);
  EXPECT_EQ(stats["windows"][0]["last"].get<int>(), 59);
  EXPECT_DOUBLE_EQ(stats["windows"][0]["keyframe_ms"].get<double>(), stats["keyframe_ms"]["median"].get<double>());

  for (const char* png : {"pr_curve.png", "loops_matrix.png"}) {
    const fs::path p = dir_ / "plots" / png;
    ASSERT_TRUE(fs::exists(p)) << p;
    EXPECT_EQ(readFile(p.string()).substr(1, 3), "PNG");
  }
}

// Every candidate is written with its probability, the ones that failed verification too (below the
// verified ones of their query), and --details carries the scorer's feature vector as columns x_*,
// which scripts/fit_scoring.py reads instead of recomputing it.
TEST_F(MildOffline, ScoresEveryCandidateAndWritesTheScorerFeatures) {
  const ProcessResult run = mildOffline("--images " + kFixture + " --config " + kFixtureConfig + " --output " +
                                        path("c.csv") + " --details " + path("d.csv"));
  ASSERT_EQ(run.status, 0) << run.output;
  std::ifstream details(path("d.csv"));
  std::string header;
  std::getline(details, header);
  std::vector<std::string> columns;
  std::stringstream hs(header);
  for (std::string c; std::getline(hs, c, ',');) columns.push_back(c);
  std::vector<size_t> feature_columns;
  for (size_t k = 0; k < columns.size(); ++k) {
    if (columns[k].rfind("x_", 0) == 0) feature_columns.push_back(k);
  }
  EXPECT_EQ(feature_columns.size(), 4u) << header;  // CandidateScorer::featureNames()
  const auto column = [&](const std::string& name) {
    return static_cast<size_t>(std::find(columns.begin(), columns.end(), name) - columns.begin());
  };
  size_t rows = 0, unverified = 0;
  std::set<std::string> written;
  std::ifstream csv(path("c.csv"));
  std::string line;
  std::getline(csv, line);
  while (std::getline(csv, line)) written.insert(line);
  for (std::string row; std::getline(details, row); ++rows) {
    std::vector<std::string> cells;
    std::stringstream rs(row);
    for (std::string c; std::getline(rs, c, ',');) cells.push_back(c);
    ASSERT_EQ(cells.size(), columns.size()) << row;
    // The geometry's evidence is its significance against chance (log10_nfa), not the raw inlier count.
    const double log10_nfa = std::stod(cells[column("log10_nfa")]);
    EXPECT_NEAR(std::stod(cells[feature_columns[1]]), std::log1p(std::max(0.0, -log10_nfa)), 1e-4) << row;
    if (std::stoi(cells[column("inliers")]) <= 7) {
      EXPECT_EQ(log10_nfa, 0.0) << "no more inliers than a minimal sample is no evidence: " << row;
    }
    if (cells[column("verified")] == "0") ++unverified;
    EXPECT_EQ(
        written.count(cells[column("query")] + "," + cells[column("candidate")] + "," + cells[column("probability")]),
        1u)
        << "every candidate is in the candidates file: " << row;
  }
  EXPECT_GT(rows, 20u);
  EXPECT_GT(unverified, 0u) << "the fixture has candidates that fail verification";
}

// 512-bit descriptors end to end through the offline runner: BRISK features, a database of their
// width, the fixture's loop found; --print-config says what ran.
TEST_F(MildOffline, RunsWithBriskDescriptors) {
  std::ofstream(path("brisk.yaml")) << readFile(kFixtureConfig) << "features: {type: brisk}\n";
  const ProcessResult run =
      mildOffline("--images " + kFixture + " --config " + path("brisk.yaml") + " --output " + path("c.csv") + " --gt " +
                  kFixture + "/gt_loops.txt --min-gap 8 --stats " + path("s.json") + " --print-config");
  ASSERT_EQ(run.status, 0) << run.output;
  EXPECT_NE(run.output.find("  type: brisk\n"), std::string::npos) << run.output;
  const size_t at = run.output.find("recall@100%P: ");
  ASSERT_NE(at, std::string::npos) << run.output;
  EXPECT_GE(std::stod(run.output.substr(at + 14)), 0.6) << run.output;
  const auto stats = nlohmann::json::parse(readFile(path("s.json")));
  EXPECT_GT(stats["features"].get<int>(), 1000);
}

TEST_F(MildOffline, PrintsTheParametersAsTheDefaultYaml) {
  const ProcessResult run = mildOffline("--print-config");
  ASSERT_EQ(run.status, 0) << run.output;
  EXPECT_EQ(run.output, readFile(std::string(MILD_SOURCE_DIR) + "/config/default.yaml"));
}

TEST_F(MildOffline, ReportsRelativePoseErrorsWithIntrinsics) {
  // The fixture's exclusion plus the bench camera: verified true loops carry a relative pose.
  std::ofstream(path("camera.yaml")) << readFile(kFixtureConfig)
                                     << "verification: {fx: 256.0, fy: 256.0, cx: 159.5, cy: 119.5}\n";
  const ProcessResult run = mildOffline("--images " + kFixture + " --config " + path("camera.yaml") + " --output " +
                                        path("c.csv") + " --gt " + kFixture + "/gt_loops.txt --min-gap 8 --poses " +
                                        kFixture + "/poses.txt --stats " + path("s.json"));
  ASSERT_EQ(run.status, 0) << run.output;
  EXPECT_NE(run.output.find("relative pose of "), std::string::npos) << run.output;
  const auto pose = nlohmann::json::parse(readFile(path("s.json")))["relative_pose"];
  EXPECT_GE(pose["poses"].get<int>(), 5) << pose.dump();
  EXPECT_LT(pose["rotation_error_deg"]["median"].get<double>(), 6.0) << pose.dump();

  const ProcessResult without = mildOffline("--images " + kFixture + " --config " + kFixtureConfig + " --output " +
                                            path("d.csv") + " --poses " + kFixture + "/poses.txt");
  ASSERT_EQ(without.status, 0) << without.output;
  EXPECT_NE(without.output.find("none estimated"), std::string::npos) << without.output;

  std::ofstream(path("short_poses.txt")) << "0 0 0\n";
  const ProcessResult wrong_count =
      mildOffline("--images " + kFixture + " --output " + path("e.csv") + " --poses " + path("short_poses.txt"));
  EXPECT_EQ(wrong_count.status, 2) << wrong_count.output;
  EXPECT_NE(wrong_count.output.find("poses for"), std::string::npos) << wrong_count.output;
}

TEST_F(MildOffline, MildScoreReportsTheConfigurationsDecision) {
  // Two loop queries (50, 60): 50 -> 0 right at 0.95, 60 -> 15 wrong at 0.93; 70 is below. Deciding
  // at 0.9 accepts both, at 0.94 only the right one; without --config the built-in default decides.
  std::ofstream(path("gt.txt")) << "50 0 0.9 1\n60 10 0.9 1\n70 20 0.1 0\n";
  std::ofstream(path("c.csv")) << "query,candidate,score\n50,0,0.95\n60,15,0.93\n70,20,0.2\n";
  std::ofstream(path("lenient.yaml")) << "scoring:\n  decision_probability: 0.9\n";
  std::ofstream(path("strict.yaml")) << "scoring:\n  decision_probability: 0.94\n";
  const std::string score = std::string(MILD_SCORE_BIN) + " " + path("gt.txt") + " " + path("c.csv");
  const ProcessResult run = mild::test::runCommand(score + " --json --config " + path("lenient.yaml"));
  ASSERT_EQ(run.status, 0) << run.output;
  const auto m = nlohmann::json::parse(mild::test::lastLine(run.output));
  EXPECT_DOUBLE_EQ(m["decision_probability"].get<double>(), 0.9);
  EXPECT_EQ(m["right_at_decision"].get<int>(), 1);
  EXPECT_EQ(m["wrong_at_decision"].get<int>(), 1);
  EXPECT_DOUBLE_EQ(m["precision_at_decision"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(m["recall_at_decision"].get<double>(), 0.5);

  const ProcessResult text = mild::test::runCommand(score + " --config " + path("strict.yaml"));
  ASSERT_EQ(text.status, 0) << text.output;
  EXPECT_NE(text.output.find("at the decision, probability >= 0.94 (scoring/decision_probability): precision 1.0000, "
                             "recall 0.5000 (1 right, 0 wrong)"),
            std::string::npos)
      << text.output;
  EXPECT_EQ(text.output.find("0.5:"), std::string::npos) << text.output;

  const ProcessResult defaults = mild::test::runCommand(score + " --json");
  ASSERT_EQ(defaults.status, 0) << defaults.output;
  const double decision = nlohmann::json::parse(mild::test::lastLine(defaults.output))["decision_probability"];
  EXPECT_GT(decision, 0.5);
  EXPECT_LE(decision, 1.0);
}

TEST_F(MildOffline, ReadsAFlatFolderOfImagesAndSkipsUnreadableFrames) {
  // Frames 0..11 of the fixture directly in a folder, frame 5 replaced by garbage.
  for (int i = 0; i < 12; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.jpg", i);
    if (i == 5) {
      std::ofstream(path(name)) << "not a jpeg";
    } else {
      fs::copy_file(kFixture + "/images/" + name, path(name));
    }
  }
  std::ofstream(path("notes.txt")) << "ignored";
  // Twelve frames are too few for the near-past band's background: without it, candidates show the numbering.
  std::ofstream(path("config.yaml")) << "detector:\n  exclusion_frames: 8\n  near_past: false\n";
  const ProcessResult run =
      mildOffline("--images " + dir_.string() + " --output " + path("c.csv") + " --config " + path("config.yaml"));
  ASSERT_EQ(run.status, 0) << run.output;
  EXPECT_NE(run.output.find("frame 5"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("000005.jpg"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("processed 11 of 12 frames"), std::string::npos) << run.output;
  // Numbering stays aligned with the file list: the last frame is still query 11, none is 5.
  const std::string csv = readFile(path("c.csv"));
  EXPECT_NE(csv.find("\n11,"), std::string::npos) << csv;
  EXPECT_EQ(csv.find("\n5,"), std::string::npos) << csv;
}

// --scale that shrinks one frame to nothing once stopped the whole run (an OpenCV exception from
// resizing to an empty size): that frame alone is skipped, as an unreadable one is.
TEST_F(MildOffline, AFrameScaledToNothingIsSkippedAlone) {
  // Frames 0..11 of the fixture (320 x 240), frame 5 a 3 x 3 grey image: at --scale 0.1 it has no pixel.
  for (int i = 0; i < 12; ++i) {
    char name[32];
    if (i == 5) {
      std::ofstream(path("000005.pgm"), std::ios::binary) << "P5\n3 3\n255\n" << std::string(9, '\x80');
      continue;
    }
    std::snprintf(name, sizeof(name), "%06d.jpg", i);
    fs::copy_file(kFixture + "/images/" + name, path(name));
  }
  std::ofstream(path("config.yaml")) << "detector:\n  exclusion_frames: 8\n  near_past: false\n";
  const ProcessResult run = mildOffline("--images " + dir_.string() + " --output " + path("c.csv") + " --config " +
                                        path("config.yaml") + " --scale 0.1");
  ASSERT_EQ(run.status, 0) << run.output;
  EXPECT_NE(run.output.find("000005.pgm"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("processed 11 of 12 frames"), std::string::npos) << run.output;
}

TEST_F(MildOffline, EmptyFolderIsAClearError) {
  const ProcessResult run = mildOffline("--images " + dir_.string() + " --output " + path("c.csv"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find(dir_.string()), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("no image files"), std::string::npos) << run.output;
}

TEST_F(MildOffline, FolderWithoutImagesIsAClearError) {
  std::ofstream(path("a.txt")) << "x";
  std::ofstream(path("b.csv")) << "y";
  const ProcessResult run = mildOffline("--images " + dir_.string() + " --output " + path("c.csv"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find("no image files"), std::string::npos) << run.output;
}

TEST_F(MildOffline, AllFramesUnreadableIsAClearError) {
  std::ofstream(path("000000.jpg")) << "garbage";
  std::ofstream(path("000001.png")) << "garbage";
  const ProcessResult run = mildOffline("--images " + dir_.string() + " --output " + path("c.csv"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find("none of the 2 image files could be read"), std::string::npos) << run.output;
}

TEST_F(MildOffline, MalformedGroundTruthFailsBeforeProcessing) {
  std::ofstream(path("gt.txt")) << "12 3 0.5 1\n12 three 0.5 1\n";
  const ProcessResult run =
      mildOffline("--images " + kFixture + " --output " + path("c.csv") + " --gt " + path("gt.txt"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find(path("gt.txt") + ":2"), std::string::npos) << run.output;
  EXPECT_EQ(run.output.find("processed"), std::string::npos) << "should fail before the run";
}

TEST_F(MildOffline, GroundTruthThatCannotBeThisSequencesIsBadInput) {
  const std::string base = "--images " + kFixture + " --output " + path("c.csv") + " --gt " + path("gt.txt");
  for (const char* gt : {"12 -3 0.5 1\n", "75 3 0.5 1\n", "", "# nothing\n"}) {  // the fixture has 60 frames
    std::ofstream(path("gt.txt")) << gt;
    const ProcessResult run = mildOffline(base);
    EXPECT_EQ(run.status, 2) << "'" << gt << "': " << run.output;
    EXPECT_NE(run.output.find(path("gt.txt")), std::string::npos) << run.output;
  }
}

TEST_F(MildOffline, AConfigThatIsAFolderIsBadInput) {
  const ProcessResult run =
      mildOffline("--images " + kFixture + " --output " + path("c.csv") + " --config " + dir_.string());
  EXPECT_EQ(run.status, 2) << run.output;
  EXPECT_NE(run.output.find("not a parameter file"), std::string::npos) << run.output;
}

TEST_F(MildOffline, BadConfigNamesTheParameter) {
  std::ofstream(path("bad.yaml")) << "filter:\n  no_loop_likelyhood: 3\n";
  const ProcessResult run =
      mildOffline("--images " + kFixture + " --output " + path("c.csv") + " --config " + path("bad.yaml"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find("filter/no_loop_likelyhood"), std::string::npos) << run.output;
}

TEST_F(MildOffline, MissingRequiredOptionsPrintUsage) {
  const ProcessResult run = mildOffline("--images " + kFixture);
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find("--output"), std::string::npos) << run.output;
}

}  // namespace
