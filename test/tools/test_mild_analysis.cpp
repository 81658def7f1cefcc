// mild_analysis as a user runs it: the table, the advisor's JSON, the plot, bad arguments.
#include <gtest/gtest.h>

#include <filesystem>

#include <nlohmann/json.hpp>

#include "../common/run_command.hpp"

namespace {

using json = nlohmann::json;

mild::test::CommandResult mildAnalysis(const std::string& args) {
  return mild::test::runCommand(std::string(MILD_ANALYSIS_BIN) + " " + args);
}

TEST(MildAnalysis, TableAsJsonCoversTheRequestedGrid) {
  const auto run = mildAnalysis("--model exact --m-range 8:16 --r-range 0:2 --json");
  ASSERT_EQ(run.status, 0) << run.output;
  const json out = json::parse(mild::test::lastLine(run.output));
  ASSERT_EQ(out["rows"].size(), 27u);
  for (const auto& row : out["rows"]) {
    EXPECT_GE(row["R"].get<double>(), 0.0);
    EXPECT_LE(row["R"].get<double>(), 1.0);
    EXPECT_LT(row["E"].get<double>(), row["R"].get<double>()) << "outliers are found less often than inliers";
    EXPECT_GT(row["E_fixed"].get<double>(), 0.0);
  }
}

TEST(MildAnalysis, RecommendsOneTableCountPerRadius) {
  const auto run = mildAnalysis("--model paper --recommend --min-accuracy 0.8 --r-range 0:2 --json");
  ASSERT_EQ(run.status, 0) << run.output;
  const json out = json::parse(mild::test::lastLine(run.output));
  ASSERT_EQ(out["recommended"].size(), 3u);
  std::vector<std::pair<int, int>> got;
  for (const auto& c : out["recommended"]) got.emplace_back(c["m"].get<int>(), c["r"].get<int>());
  EXPECT_EQ(got, (std::vector<std::pair<int, int>>{{15, 0}, {11, 1}, {8, 2}}));
  EXPECT_EQ(out["choice"]["m"].get<int>(), 15) << "online, the fixed cost decides";
  EXPECT_FALSE(out["explanation"].get<std::string>().empty());

  const auto offline = mildAnalysis("--model paper --recommend --min-accuracy 0.8 --r-range 0:2 --offline --json");
  ASSERT_EQ(offline.status, 0) << offline.output;
  EXPECT_EQ(json::parse(mild::test::lastLine(offline.output))["choice"]["r"].get<int>(), 2);
}

TEST(MildAnalysis, DrawsThePlot) {
  const std::filesystem::path png =
      std::filesystem::temp_directory_path() / ("mild_analysis_" + std::to_string(::getpid()) + ".png");
  const auto run = mildAnalysis("--model exact --m-range 4:24 --r-range 0:2 --plot " + png.string());
  ASSERT_EQ(run.status, 0) << run.output;
  ASSERT_TRUE(std::filesystem::exists(png));
  EXPECT_GT(std::filesystem::file_size(png), 10000u);
  std::filesystem::remove(png);
}

TEST(MildAnalysis, BadArgumentsAreClearErrors) {
  auto run = mildAnalysis("--model uniform");
  EXPECT_EQ(run.status, 2);
  EXPECT_NE(run.output.find("'paper' or 'exact'"), std::string::npos) << run.output;
  run = mildAnalysis("--m-range 4-32");
  EXPECT_EQ(run.status, 2);
  EXPECT_NE(run.output.find("--m-range"), std::string::npos) << run.output;
  run = mildAnalysis("--recommend --min-accuracy 1.5");
  EXPECT_EQ(run.status, 2);
  EXPECT_NE(run.output.find("reaches accuracy"), std::string::npos) << run.output;
  run = mildAnalysis("--priors /nonexistent/priors.json");
  EXPECT_EQ(run.status, 2);
  EXPECT_NE(run.output.find("/nonexistent/priors.json"), std::string::npos) << run.output;
}

TEST(MildAnalysis, MeasuresPriorsOnASequenceWithGroundTruth) {
  const std::filesystem::path out =
      std::filesystem::temp_directory_path() / ("priors_" + std::to_string(::getpid()) + ".json");
  const auto run = mildAnalysis("--measure-priors " + std::string(MILD_SOURCE_DIR) +
                                "/sample/corridor --pairs 40 --output " + out.string() + " --json");
  ASSERT_EQ(run.status, 0) << run.output;
  const json summary = json::parse(mild::test::lastLine(run.output));
  EXPECT_NEAR(summary["inlier_mean"].get<double>(), 34.0, 6.0);
  EXPECT_NEAR(summary["outlier_mean"].get<double>(), 125.0, 8.0);
  for (const auto& v : summary["validation"]) {
    EXPECT_NEAR(v["index_found"].get<double>(), v["R_exact"].get<double>(), 0.04) << v.dump();
  }
  // The file feeds the advisor.
  const auto advised = mildAnalysis("--recommend --priors " + out.string() + " --json");
  EXPECT_EQ(advised.status, 0) << advised.output;
  std::filesystem::remove(out);
}

}  // namespace
