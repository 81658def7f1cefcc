// test_ros_parts: live tuning's cfg and its requests (ros/tuning_config.hpp).

#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

// dynamic_reconfigure (the generated cfg, tuning_cfg.hpp) serves exactly the runtime parameters, with the detector's
// defaults and ranges the detector accepts; its values travel through the parameter registry.
TEST(Tuning, TheCfgIsTheRuntimeParametersWithTheDetectorsDefaultsAndRanges) {
  std::set<std::string> cfg, runtime;
  for (const auto& d : mild_lcd::TuningConfig::__getParamDescriptions__()) cfg.insert(d->name);
  for (const std::string& name : mild::runtimeParameterNames()) runtime.insert(tuningName(name));
  EXPECT_EQ(cfg, runtime);

  const mild::DetectorParams defaults;
  EXPECT_EQ(mild::describeParameters(paramsFromTuning(mild_lcd::TuningConfig::__getDefault__(), defaults)),
            mild::describeParameters(defaults))
      << "the generated cfg's defaults differ from the detector's";
  for (const auto& bound : {mild_lcd::TuningConfig::__getMin__(), mild_lcd::TuningConfig::__getMax__()}) {
    mild::LoopDetector detector;
    EXPECT_NO_THROW(detector.retune(paramsFromTuning(bound, defaults))) << "a cfg bound the detector refuses";
  }

  mild::DetectorParams custom;
  custom.candidates.max_candidates = 7;
  custom.scoring.decision_probability = 0.75;
  const mild_lcd::TuningConfig config = tuningConfigOf(custom);
  EXPECT_EQ(config.detector_max_candidates, 7);
  EXPECT_EQ(config.scoring_decision_probability, 0.75);
  EXPECT_EQ(config.detector_exclusion_frames, custom.candidates.exclusion_frames);
  EXPECT_EQ(mild::describeParameters(paramsFromTuning(config, mild::DetectorParams{})),
            mild::describeParameters(custom))
      << "there and back";

  // What the server writes under ~tuning is known to the start-up check; nothing else there is.
  EXPECT_EQ(errorOf([] {
              rejectUnknownParameters(YamlParameterSource::fromString("tuning:\n  detector_max_candidates: 2\n"));
            }),
            "");
  EXPECT_NE(errorOf([] {
              rejectUnknownParameters(YamlParameterSource::fromString("tuning:\n  index_num_tables: 2\n"));
            }).find("tuning/index_num_tables"),
            std::string::npos);
}

// dynamic_reconfigure's parsing skips entries it cannot place; the node names them and refuses the
// request.
TEST(Tuning, EntriesThatNameNoParameterOrHaveTheWrongTypeAreNamed) {
  dynamic_reconfigure::Config request;
  dynamic_reconfigure::IntParameter i;
  i.name = "detector_max_candidates";
  i.value = 2;
  request.ints.push_back(i);
  dynamic_reconfigure::DoubleParameter d;
  d.name = "scoring_decision_probability";
  d.value = 0.7;
  request.doubles.push_back(d);
  EXPECT_EQ(unreadTuningEntries(request), "");
  EXPECT_EQ(unreadTuningEntries({}), "") << "an empty request (a get)";
  d.name = "detector_max_candidates";  // an int parameter given as a double
  request.doubles.push_back(d);
  dynamic_reconfigure::BoolParameter b;
  b.name = "index_num_tables";  // not a runtime parameter
  request.bools.push_back(b);
  const std::string problems = unreadTuningEntries(request);
  EXPECT_NE(problems.find("'detector_max_candidates' takes int values, not double"), std::string::npos) << problems;
  EXPECT_NE(problems.find("'index_num_tables' is not a tuning parameter"), std::string::npos) << problems;
}

}  // namespace
}  // namespace mild_lcd
