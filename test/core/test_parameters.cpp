#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/params/parameters.hpp"

namespace mild {
namespace {

std::string configPath(const std::string& name) { return std::string(MILD_SOURCE_DIR) + "/config/" + name; }

TEST(Parameters, DefaultYamlDocumentsEveryParameterWithItsBuiltInDefault) {
  const YamlParameterSource yaml = YamlParameterSource::fromFile(configPath("default.yaml"));
  const auto names = yaml.names();
  const std::set<std::string> in_file(names.begin(), names.end());
  for (const auto& [name, value] : describeParameters(DetectorParams{})) {
    EXPECT_TRUE(in_file.count(name)) << name << " is missing from config/default.yaml";
  }
  EXPECT_EQ(describeParameters(loadDetectorParams(yaml)), describeParameters(DetectorParams{}))
      << "config/default.yaml and the built-in defaults disagree";
}

TEST(Parameters, ReadsNestedYamlAndKeepsDefaultsForTheRest) {
  const auto source = YamlParameterSource::fromString(R"(
orb:
  num_features: 500
index: {num_tables: 24, radius: 1}
similarity:
  search: exact
filter:
  motion_kernel: [1, 2]
detector:
  exclusion_seconds: 2.5
)");
  const DetectorParams p = loadDetectorParams(source);
  EXPECT_EQ(p.orb.num_features, 500);
  EXPECT_EQ(p.database.index.num_tables, 24);
  EXPECT_EQ(p.database.index.radius, 1);
  EXPECT_EQ(p.search, SearchMode::kExact);
  EXPECT_EQ(p.filter.motion_kernel, (std::vector<double>{1.0, 2.0}));
  EXPECT_DOUBLE_EQ(p.candidates.exclusion_seconds, 2.5);
  EXPECT_EQ(p.candidates.exclusion_frames, DetectorParams{}.candidates.exclusion_frames);
}

void expectRejected(const std::string& yaml, const std::string& mention) {
  try {
    loadDetectorParams(YamlParameterSource::fromString(yaml, "test.yaml"));
    ADD_FAILURE() << "accepted: " << yaml;
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find(mention), std::string::npos) << e.what();
  }
}

TEST(Parameters, RejectsBadValuesNamingTheParameter) {
  expectRejected("orb: {num_featurs: 500}", "orb/num_featurs");     // typo
  expectRejected("orb: {num_features: many}", "orb/num_features");  // wrong type
  expectRejected("orb: {num_features: 0}", "orb/num_features");     // out of range
  expectRejected("index: {radius: 7}", "index/radius");
  expectRejected("index: {num_tables: 3}", "index/num_tables");
  expectRejected("similarity: {sigma2: 0}", "similarity/sigma2");
  expectRejected("verification: {num_tables: 8}", "verification/num_tables");
  expectRejected("index: {min_bucket_cap: -3}", "index/min_bucket_cap");  // unsigned
  expectRejected("similarity: {search: fast}", "similarity/search");
  expectRejected("filter: {loop_onset: 2}", "filter/loop_onset");
  expectRejected("filter: {motion_kernel: 3}", "filter/motion_kernel");  // not a list
  expectRejected("filter: {motion_kernel: [a, b]}", "filter/motion_kernel");
  expectRejected("detector: {max_candidates: 0}", "detector/max_candidates");
  expectRejected("detector: {min_probability: 1.5}", "detector/min_probability");
  expectRejected("index: {cap_buckets: maybe}", "index/cap_buckets");
  expectRejected("orb: [1, 2]", "orb");
  expectRejected("orb: {num_features: [1, 2]", "test.yaml");  // not YAML
  expectRejected("- 1\n- 2\n", "top level");
}

TEST(Parameters, IgnoresNamesOutsideTheDetectorsNamespaces) {
  // The nodelet keeps its own settings (topics, queue size) beside the detector's.
  const auto source = YamlParameterSource::fromString("queue_size: 5\nuse_image_input: true\n");
  EXPECT_NO_THROW(loadDetectorParams(source));
}

TEST(Parameters, UnreadableFileIsNamed) {
  try {
    YamlParameterSource::fromFile("/nonexistent/mild.yaml");
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/mild.yaml"), std::string::npos);
  }
}

}  // namespace
}  // namespace mild
