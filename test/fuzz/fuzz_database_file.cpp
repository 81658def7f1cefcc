// libFuzzer target: the database file loader. Any bytes must give a MapState or InvalidInput,
// and a parsed state must restore into a detector or be refused with InvalidInput; never a crash,
// a sanitizer report, or an unbounded allocation. Built with FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
// so that the checksums do not stop the fuzzer at the door.
#include <cstddef>
#include <cstdint>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/io/database_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const mild::DetectorParams params = [] {
    mild::DetectorParams p;
    p.database.index.num_tables = 8;  // 32-bit substrings: hashed tables, cheap to set up per input
    p.database.index.expected_features = 10000;
    p.verification.enabled = false;
    return p;
  }();
  try {
    mild::MapState state = mild::parseMapState(data, size, "fuzz input");
    mild::LoopDetector detector(params);
    const bool continue_session = size % 2 == 0;
    detector.map().restore(std::move(state), continue_session);
    // The restored detector must work.
    mild::Features features;
    features.keypoints.resize(2);
    features.descriptors.resize(2);
    detector.process(mild::Observation::ofFeatures(features, 1e9));
  } catch (const mild::Error&) {
  }
  return 0;
}
