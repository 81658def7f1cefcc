// test_ros_parts: the node's settings (ros/node_settings.hpp): types, names, docs/parameters.md's table, defaults.

#include "mild_lcd/team/station.hpp"
#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

TEST(NodeSettings, WrongTypesAndMisspeltNamesAreErrorsNamingThem) {
  EXPECT_NE(errorOf([] { settingsFrom("save_on_shutdown: \"true\"\n"); }).find("save_on_shutdown"), std::string::npos)
      << "a string where a boolean belongs";
  EXPECT_NE(errorOf([] { settingsFrom("queue_size: 2.5\n"); }).find("queue_size"), std::string::npos);
  EXPECT_NE(errorOf([] { settingsFrom("queue_size: 0\n"); }).find("queue_size"), std::string::npos);
  const std::string typo =
      errorOf([] { rejectUnknownParameters(YamlParameterSource::fromString("queue_sise: 10\n")); });
  EXPECT_NE(typo.find("~queue_sise"), std::string::npos) << typo;
  EXPECT_NE(typo.find("queue_size"), std::string::npos) << "lists the real names: " << typo;
  EXPECT_EQ(errorOf([] {
              rejectUnknownParameters(YamlParameterSource::fromString(
                  "queue_size: 10\ndiagnostic_period: 1.0\norb:\n  num_features: 500\n"));
            }),
            "")
      << "the node's, the detector's and diagnostic_updater's names are known";
  EXPECT_NE(
      errorOf([] { settingsFrom("use_image_input: false\nuse_keyframe_input: false\n"); }).find("nothing to listen"),
      std::string::npos);
  EXPECT_NE(errorOf([] { settingsFrom("load_on_start: true\n"); }).find("database_path"), std::string::npos);
  EXPECT_NE(errorOf([] { settingsFrom("database_dir: maps\n"); }).find("absolute"), std::string::npos);
}

// The ~team/ parameters are the station protocol's settings, and a node serving one robot (named
// "" in its maps) names it on the wire by its station.
TEST(NodeSettings, TheTeamParametersAreTheStationsSettings) {
  const NodeSettings s = settingsFrom(
      "team:\n  station: alpha\n  summary_bytes: 4096\n  backfill_batch: 7\n  peer_timeout: 2.5\n"
      "  max_requests_per_second: 40\n  max_pending_pulls: 9\nmax_keyframe_features: 3000\n");
  const mild::StationSettings one = s.stationSettings({""});
  EXPECT_EQ(one.station, "alpha");
  EXPECT_EQ(one.robots, std::vector<std::string>{"alpha"});
  EXPECT_EQ(one.summary_bytes, 4096u);
  EXPECT_EQ(one.backfill_batch, 7u);
  EXPECT_DOUBLE_EQ(one.peer_timeout, 2.5);
  EXPECT_DOUBLE_EQ(one.max_requests_per_second, 40.0);
  EXPECT_EQ(one.max_pending_pulls, 9u);
  EXPECT_EQ(one.max_keyframe_features, 3000u);
  EXPECT_EQ(s.stationSettings({"robot1", "robot2"}).robots, (std::vector<std::string>{"robot1", "robot2"}));
}

// BRISK and AKAZE on images as large as ~max_image_pixels allows can hold the worker for minutes:
// the node says so at start-up, unless the bound keeps images small or the input is features.
TEST(NodeSettings, WarnsOfCostlyExtractionOnLargeImages) {
  EXPECT_EQ(extractionCostWarning(settingsFrom(""), "orb"), "");
  EXPECT_NE(extractionCostWarning(settingsFrom(""), "akaze").find("~max_image_pixels (16777216)"), std::string::npos);
  EXPECT_NE(extractionCostWarning(settingsFrom(""), "brisk"), "");
  EXPECT_EQ(extractionCostWarning(settingsFrom("max_image_pixels: 4194304\n"), "akaze"), "");
  EXPECT_EQ(extractionCostWarning(settingsFrom("use_image_input: false\n"), "akaze"), "");
}

TEST(NodeSettings, TheParameterPageIsTheDeclaration) {
  std::ifstream in(std::string(MILD_SOURCE_DIR) + "/docs/parameters.md");
  const std::string page((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(page.find(nodeSettingsMarkdown()), std::string::npos)
      << "docs/parameters.md's node parameter table is out of date; it must read exactly:\n"
      << nodeSettingsMarkdown();
}

TEST(NodeSettings, TheDatabaseFolderDefaultsToThePathsFolderOrRosHome) {
  EXPECT_EQ(settingsFrom("").database_dir, "/tmp/mild_default");
  EXPECT_EQ(settingsFrom("database_path: /data/maps/site.db\n").database_dir, "/data/maps");
  EXPECT_EQ(settingsFrom("database_path: site.db\n").database_dir, "/tmp/mild_default");
  EXPECT_EQ(settingsFrom("database_dir: /srv/maps\ndatabase_path: site.db\n").database_dir, "/srv/maps");
  EXPECT_FALSE(nodeSettingDocs().empty());
}

}  // namespace
}  // namespace mild_lcd
