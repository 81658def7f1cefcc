// The benchmarks as a user runs them, on tiny inputs: they finish, and their output (a --json line,
// or mild_bench_ledger's table) carries the figures docs/speed.md and docs/multi_robot.md report.
// (Their speed is not tested here: benchmarks measure, tests check.)
#include <gtest/gtest.h>
#include <cctype>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "../common/run_command.hpp"

namespace {

using json = nlohmann::json;
const std::string kSample = std::string(MILD_SOURCE_DIR) + "/sample/corridor";

TEST(MildBenchMatch, PrintsBothRatiosAndTheRecoveredFractions) {
  const auto run = mild::test::runCommand(std::string(MILD_BENCH_MATCH_BIN) + " --images " + kSample +
                                          " --pairs 6 --repeats 1 --scale 2 --json");
  ASSERT_EQ(run.status, 0) << run.output;
  EXPECT_NE(run.output.find("faster than brute force"), std::string::npos) << run.output;
  const json out = json::parse(mild::test::lastLine(run.output));
  for (const char* key : {"bf_over_sparse", "lsh_over_sparse", "sparse_recovery", "lsh_recovery", "sparse_ms_median"}) {
    ASSERT_TRUE(out.contains(key)) << key;
    EXPECT_GT(out[key].get<double>(), 0.0) << key;
  }
  EXPECT_EQ(out["pairs"].get<int>(), 6);
  EXPECT_LE(out["sparse_recovery"].get<double>(), 1.0);
  EXPECT_GT(out["sparse_recovery"].get<double>(), 0.8) << "sparse match finds most brute-force pairs under 50 bits";
}

TEST(MildBenchTeam, ReportsEachTeamSizeAgainstTheFirstAndFindsTheOtherRobotsPlaces) {
  // Two robots walking the same corridor: every place of robot 2 is in robot 1's map.
  const auto run = mild::test::runCommand(std::string(MILD_BENCH_TEAM_BIN) + " --walk " + kSample + " --walk " +
                                          kSample + " --robots 1,2 --keyframes 80 --json");
  ASSERT_EQ(run.status, 0) << run.output;
  const json out = json::parse(mild::test::lastLine(run.output));
  ASSERT_EQ(out["rows"].size(), 2u);
  const json& lone = out["rows"][0];
  const json& pair = out["rows"][1];
  EXPECT_EQ(lone["robots"].get<int>(), 1);
  EXPECT_EQ(lone["keyframes"].get<int>(), 80);
  EXPECT_EQ(pair["keyframes"].get<int>(), 160) << "every robot's keyframes, interleaved";
  EXPECT_DOUBLE_EQ(lone["ratio_to_first"].get<double>(), 1.0);
  EXPECT_GT(pair["cpu_ms_median"].get<double>(), 0.0);
  EXPECT_EQ(lone["inter_robot_candidates_per_keyframe"].get<double>(), 0.0) << "a lone robot has no other map";
  EXPECT_GT(pair["inter_robot_candidates_per_keyframe"].get<double>(), 0.0);
  const auto short_team =
      mild::test::runCommand(std::string(MILD_BENCH_TEAM_BIN) + " --walk " + kSample + " --robots 1,2 --keyframes 5");
  EXPECT_EQ(short_team.status, 2) << "a team of two needs two walks: " << short_team.output;
  EXPECT_NE(short_team.output.find("needs as many --walk"), std::string::npos) << short_team.output;
}

// One row per ledger: the loops held, its text's bytes (growing with the loops), the copy made
// under the detector lock and the text made after it; a count beyond what a ledger keeps is refused.
TEST(MildBenchLedger, ReportsTheCopyAndTheTextOfEachLedger) {
  const auto run = mild::test::runCommand(std::string(MILD_BENCH_LEDGER_BIN) +
                                          " --loops 10,1000 --own 50 --announced 50 --repeats 1");
  ASSERT_EQ(run.status, 0) << run.output;
  std::istringstream lines(run.output);
  std::vector<std::vector<double>> rows;
  for (std::string line; std::getline(lines, line);) {
    if (line.empty() || !std::isdigit(static_cast<unsigned char>(line[0]))) continue;
    std::vector<double> row;
    std::istringstream cells(line);
    for (std::string cell; std::getline(cells, cell, '|');) row.push_back(std::stod(cell));
    rows.push_back(row);
  }
  ASSERT_EQ(rows.size(), 2u) << run.output;
  EXPECT_EQ(rows[0][0], 10.0);
  EXPECT_EQ(rows[1][0], 1000.0);
  EXPECT_GT(rows[1][1], rows[0][1] + 990 * 20) << "each loop held is in the text";
  EXPECT_GT(rows[1][2], 0.0);
  EXPECT_GT(rows[1][3], 0.0);
  const auto beyond = mild::test::runCommand(std::string(MILD_BENCH_LEDGER_BIN) + " --loops 100001");
  EXPECT_EQ(beyond.status, 2) << beyond.output;
}

TEST(MildBenchScale, ReportsEveryColumnPerSize) {
  const auto run = mild::test::runCommand(std::string(MILD_BENCH_SCALE_BIN) + " --images " + kSample +
                                          " --sizes 30,60 --features 200 --queries 3 --brute-queries 1 "
                                          "--persistence-keyframes 20 --json");
  ASSERT_EQ(run.status, 0) << run.output;
  const json out = json::parse(mild::test::lastLine(run.output));
  ASSERT_EQ(out["rows"].size(), 2u);
  for (const auto& row : out["rows"]) {
    for (const char* key : {"keyframes", "mih_ms_median", "mih_et_ms_median", "baseline_2017_ms_median",
                            "brute_ms_median", "bytes_per_feature", "mih_bounded_ms_median", "default_ms_median",
                            "faiss_multihash_ms_median", "mih_inline_ms_median", "inline_bytes_per_feature",
                            "default_bytes_per_feature", "insert_ms_last_tenth", "insert_ms_max"}) {
      ASSERT_TRUE(row.contains(key)) << key << " in " << row.dump();
    }
    EXPECT_GT(row["bytes_per_feature"].get<double>(), 32.0) << "at least the descriptor";
    EXPECT_EQ(row["default_ms_median"], row["mih_bounded_ms_median"]) << "the shipped configuration is bounded";
    EXPECT_GT(row["bound"].get<int>(), 0) << "the shipped bound (index/max_bucket_entries)";
    ASSERT_GT(row["query_budget"].get<int>(), 0) << "the shipped query budget (index/max_candidates_per_feature)";
    EXPECT_LE(row["default_candidates_per_query_feature"].get<double>(), row["query_budget"].get<double>());
    EXPECT_LE(row["insert_ms_last_tenth"].get<double>(), row["insert_ms_max"].get<double>());
    EXPECT_GT(row["inline_bytes_per_feature"].get<double>(), row["bytes_per_feature"].get<double>());
#if !MILD_HAVE_FAISS
    // Built without faiss (-DMILD_WITH_FAISS=OFF or no libfaiss-dev): its columns are there, empty.
    EXPECT_TRUE(row["faiss_mih_ms_median"].is_null()) << row.dump();
    EXPECT_FALSE(out["faiss"].get<bool>());
    EXPECT_NE(run.output.find("built without faiss"), std::string::npos) << run.output;
    continue;
#endif
    // faiss answers the database's question on the same descriptors: pairs within d0, MIH a subset.
    EXPECT_TRUE(out["faiss"].get<bool>());
    ASSERT_TRUE(row["faiss_mih_ms_median"].is_number()) << row.dump();
    const auto exact_pairs = row["faiss_exact_pairs_first_query"].get<size_t>();
    const auto mih_pairs = row["faiss_mih_pairs_first_query"].get<size_t>();
    EXPECT_GT(exact_pairs, 0u) << "queries revisit stored frames, so features within d0 exist";
    EXPECT_GT(mih_pairs, 0u);
    EXPECT_LE(mih_pairs, exact_pairs) << "multi-index hashing finds a subset of the exact pairs";
  }
  EXPECT_EQ(out["persistence"]["keyframes"].get<int>(), 20);
  EXPECT_GT(out["persistence"]["load_s"].get<double>(), 0.0);
  const auto bad = mild::test::runCommand(std::string(MILD_BENCH_SCALE_BIN) + " --sizes 1k");
  EXPECT_EQ(bad.status, 2);
  EXPECT_NE(bad.output.find("--sizes"), std::string::npos) << bad.output;
}

TEST(MildBenchScale, BuildsTheDatabaseFromARealWalk) {
  // The sample's 300 frames: 5 held out as queries, sizes as prefixes of the rest and the whole walk.
  const auto run = mild::test::runCommand(std::string(MILD_BENCH_SCALE_BIN) + " --sequence " + kSample +
                                          " --sizes 100,1000 --features 200 --queries 5 --brute-queries 1 "
                                          "--skip-baseline --persistence-keyframes 0 --json");
  ASSERT_EQ(run.status, 0) << run.output;
  const json out = json::parse(mild::test::lastLine(run.output));
  EXPECT_EQ(out["keyframes_from"], "sequence");
  EXPECT_EQ(out["queries"].get<int>(), 5);
  ASSERT_EQ(out["rows"].size(), 2u) << "1000 is beyond the walk: 100 and the whole walk remain";
  EXPECT_EQ(out["rows"][0]["keyframes"].get<int>(), 100);
  EXPECT_EQ(out["rows"][1]["keyframes"].get<int>(), 295);
  const auto too_many = mild::test::runCommand(std::string(MILD_BENCH_SCALE_BIN) + " --sequence " + kSample +
                                               " --queries 400 --persistence-keyframes 0");
  EXPECT_EQ(too_many.status, 2) << too_many.output;
  EXPECT_NE(too_many.output.find("readable frames"), std::string::npos) << too_many.output;
}

}  // namespace
