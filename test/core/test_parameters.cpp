#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <set>
#include <sstream>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"

namespace mild {
namespace {

std::string configPath(const std::string& name) { return std::string(MILD_SOURCE_DIR) + "/config/" + name; }

TEST(Parameters, DefaultYamlIsGeneratedFromTheDeclarations) {
  std::ifstream in(configPath("default.yaml"));
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(text.str(), parameterYaml(DetectorParams{}))
      << "config/default.yaml differs from the declarations: regenerate it with "
         ".build/devel/lib/mild_lcd/mild_offline --print-config > config/default.yaml";
}

TEST(Parameters, TheParameterPageIsTheDeclaration) {
  std::ifstream in(std::string(MILD_SOURCE_DIR) + "/docs/parameters.md");
  std::stringstream page;
  page << in.rdbuf();
  EXPECT_NE(page.str().find(parameterMarkdown()), std::string::npos)
      << "docs/parameters.md's detector parameter table is out of date; `mild_offline --help-parameters` prints it:\n"
      << parameterMarkdown();
}

TEST(Parameters, BoundsComeFromTheDeclarationAndNameTheParameter) {
  // The message is built from the declared bounds, whichever struct validates.
  MihParams index;
  index.num_tables = 3;
  try {
    index.validate();
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_STREQ(e.what(), "index/num_tables must be 0 or [4, 64], got 3");
  }
  FilterParams filter;
  filter.section<ExclusiveHypothesisParams>().motion_kernel = {0.5, -1.0};
  try {
    filter.validate();
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_STREQ(e.what(), "exclusive_hypotheses/motion_kernel must list 1 to 64 numbers, each >= 0, got the item -1");
  }
  FeatureParams features;
  features.type = "sift";
  EXPECT_THROW(features.validate(), InvalidInput);
  // Each declared parameter's default lies within its bounds, and every bound is checked: a value
  // outside is refused with the parameter's name.
  const DetectorParams defaults;
  EXPECT_NO_THROW(defaults.validate());
  size_t declared = 0;
  visitParameters(defaults, [&](const std::string& name, const auto& field, const Bounds& bounds, const char* doc) {
    ++declared;
    EXPECT_GT(std::string(doc).size(), 10u) << name << " needs a meaning";
    EXPECT_NO_THROW(bounds.check(name, field)) << name;
  });
  EXPECT_EQ(declared, describeParameters(defaults).size());
  // The runtime set is what the declarations mark, and only candidate, verification and scoring
  // parameters are in it.
  const auto& runtime = runtimeParameterNames();
  EXPECT_EQ(runtime.size(), 11u);
  for (const std::string& name : runtime) {
    EXPECT_TRUE(name.rfind("detector/", 0) == 0 || name.rfind("verification/", 0) == 0 ||
                name.rfind("scoring/", 0) == 0)
        << name;
  }
}

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

// The shipped presets load and validate, and say what they change: the most accurate one on real
// frames is AKAZE with nothing else changed, the one within a keyframe's budget AKAZE on capped
// frames with a cheaper scale space and a lower threshold (docs/accuracy.md, the cost-accuracy frontier).
TEST(Parameters, ShippedPresetsLoadAndChangeWhatTheySay) {
  const DetectorParams accurate =
      loadDetectorParams(YamlParameterSource::fromFile(configPath("real_cameras_accurate.yaml")));
  EXPECT_NO_THROW(accurate.validate());
  EXPECT_EQ(accurate.features.type, "akaze");
  DetectorParams expected;
  expected.features.type = "akaze";
  EXPECT_EQ(describeParameters(accurate), describeParameters(expected)) << "the descriptor alone changes";
  // Within a keyframe's budget: AKAZE on frames capped at 320 x 240, one sub-level per octave.
  const DetectorParams budget =
      loadDetectorParams(YamlParameterSource::fromFile(configPath("real_cameras_budget.yaml")));
  EXPECT_NO_THROW(budget.validate());
  expected.features.max_pixels = 320.0 * 240.0;
  expected.features.section<AkazeParams>().octave_layers = 1;
  expected.features.section<AkazeParams>().threshold = 0.00005;
  expected.candidates.near_past_rise = 3.0;  // the band's rise before 0.7.1: what these features were measured with
  EXPECT_EQ(describeParameters(budget), describeParameters(expected))
      << "the descriptor, the cap, AKAZE's scale space and the near-past band's rise alone change";
  const DetectorParams camera = loadDetectorParams(YamlParameterSource::fromFile(configPath("bench_camera.yaml")));
  EXPECT_NO_THROW(camera.validate());
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
  EXPECT_EQ(p.features.section<OrbParams>().num_features, 500);
  EXPECT_EQ(p.database.index.num_tables, 24);
  EXPECT_EQ(p.database.index.radius, 1);
  EXPECT_EQ(p.search, SearchMode::kExact);
  EXPECT_EQ(p.filter.section<ExclusiveHypothesisParams>().motion_kernel, (std::vector<double>{1.0, 2.0}))
      << "filter/motion_kernel, the name of earlier versions, still sets it";
  EXPECT_DOUBLE_EQ(p.candidates.exclusion_seconds, 2.5);
  EXPECT_EQ(p.candidates.exclusion_frames, DetectorParams{}.candidates.exclusion_frames);
}

// Each filter reads its own section; the names filter/<name> of earlier versions set <name> in every
// filter's section that has it, and the current name decides when both are given.
TEST(Parameters, EachFilterHasItsOwnSectionAndTheEarlierNamesStillWork) {
  const DetectorParams p = loadDetectorParams(YamlParameterSource::fromString(R"(
filter:
  loop_persistence: 0.9
  no_loop_likelihood: 7
exclusive_hypotheses:
  loop_onset: 0.02
  no_loop_likelihood: 8
independent_binary:
  loop_persistence: 0.8
)"));
  const auto& exclusive = p.filter.section<ExclusiveHypothesisParams>();
  const auto& independent = p.filter.section<IndependentBinaryParams>();
  EXPECT_DOUBLE_EQ(exclusive.loop_persistence, 0.9);
  EXPECT_DOUBLE_EQ(exclusive.loop_onset, 0.02);
  EXPECT_DOUBLE_EQ(exclusive.no_loop_likelihood, 8.0);
  EXPECT_DOUBLE_EQ(independent.loop_persistence, 0.8);
  EXPECT_DOUBLE_EQ(independent.no_loop_likelihood, 7.0);
  // independent_binary neither reads nor documents the knobs it ignores.
  for (const auto& [name, value] : describeParameters(DetectorParams{}, IndependentBinaryParams::kSection)) {
    EXPECT_TRUE(name == "independent_binary/loop_persistence" || name == "independent_binary/no_loop_likelihood")
        << name;
  }
  EXPECT_THROW(loadDetectorParams(YamlParameterSource::fromString("independent_binary: {loop_onset: 0.1}")),
               InvalidInput);
  EXPECT_EQ(legacyParameterName("exclusive_hypotheses/loop_onset"), "filter/loop_onset");
  EXPECT_EQ(legacyParameterName("orb/num_features"), "");
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
  expectRejected("exclusive_hypotheses: {loop_onset: 2}", "exclusive_hypotheses/loop_onset");
  expectRejected("exclusive_hypotheses: {motion_kernel: 3}", "exclusive_hypotheses/motion_kernel");  // not a list
  expectRejected("exclusive_hypotheses: {motion_kernel: [a, b]}", "exclusive_hypotheses/motion_kernel");
  expectRejected("filter: {motion_kernel: 3}", "filter/motion_kernel");  // an earlier name, as written
  expectRejected("filter: {loop_onset: 2}", "exclusive_hypotheses/loop_onset");
  expectRejected("independent_binary: {no_loop_likelihood: 0}", "independent_binary/no_loop_likelihood");
  expectRejected("detector: {max_candidates: 0}", "detector/max_candidates");
  // Each candidate is verified: unbounded counts made a keyframe's work the whole map's.
  expectRejected("detector: {max_candidates: 101}", "detector/max_candidates");
  expectRejected("detector: {similarity_candidates: 2147483647}", "detector/similarity_candidates");
  expectRejected("scoring: {weights: [1e308, 1e308, 0, 0]}", "scoring/weights");
  expectRejected("scoring: {bias: -1e308}", "scoring/bias");
  expectRejected("index: {bucket_cap_factor: 0}", "index/bucket_cap_factor");
  expectRejected("detector: {min_probability: 1.5}", "detector/min_probability");
  expectRejected("index: {cap_buckets: maybe}", "index/cap_buckets");
  expectRejected("orb: [1, 2]", "orb");
  expectRejected("orb: {num_features: [1, 2]", "test.yaml");  // not YAML
  expectRejected("- 1\n- 2\n", "top level");
  expectRejected("features: {type: sift}", "features/type");
  expectRejected("features: {descriptor_bytes: 4}", "features/descriptor_bytes");
  expectRejected("brisk: {threshold: 0}", "brisk/threshold");
  expectRejected("akaze: {threshold: 2}", "akaze/threshold");
  // Width-dependent: 20-bit substrings at most for sparse match, 64 for the index.
  expectRejected("features: {type: brisk}\nverification: {num_tables: 22}", "verification/num_tables");
  expectRejected("features: {type: brisk}\nindex: {num_tables: 4}",
                 "index/num_tables must be 0 (automatic) or at least 8 for 512-bit");
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
