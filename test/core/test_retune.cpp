// Every parameter declared runtime() takes effect when a running detector is retuned: a detector
// retuned to a changed value before its first keyframe gives exactly the outputs of one built with
// that value, and those differ from the defaults' outputs. A parameter flagged runtime() that
// retune does not apply (or applies only in part) fails here; one flagged without an entry in
// kChangedValues fails too, so the flag cannot be added without this check.

#include <gtest/gtest.h>

#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "test_images.hpp"

namespace mild {
namespace {

// A value of each runtime parameter that changes the outputs on the frames below.
const std::map<std::string, std::string> kChangedValues = {
    {"detector/exclusion_frames", "10"},
    {"detector/exclusion_seconds", "16.0"},  // 80 keyframes at 0.2 s: more than exclusion_frames
    {"detector/max_candidates", "1"},
    {"detector/suppression_radius", "40"},
    {"detector/min_probability", "0.5"},
    {"detector/similarity_candidates", "0"},  // only the filter's candidates are judged
    {"scoring/decision_probability", "0.95"},
    {"verification/ransac_threshold", "0.3"},
    {"verification/min_inliers", "60"},
    {"verification/pnp_threshold", "0.5"},  // the keyframes bring a camera and depths: poses are PnP's
    {"verification/ratio", "0.6"},
};

// Every second frame of the embedded sample (it loops), with a camera and a depth per keypoint,
// extracted once: each run below then costs only the detector's own work.
const std::vector<Features>& keyframes() {
  static const std::vector<Features> out = [] {
    const auto extractor = makeFeatureExtractor(FeatureParams{});
    std::vector<Features> frames;
    const std::vector<cv::Mat>& images = test::sampleFrames();
    for (size_t i = 0; i < images.size(); i += 2) {
      Features f = extractor->extract(images[i], PixelFormat::kGray);
      f.camera = CameraIntrinsics{320.0, 320.0, 320.0, 240.0};
      f.depths.assign(f.keypoints.size(), 3.0f);
      frames.push_back(std::move(f));
    }
    return frames;
  }();
  return out;
}

// Everything a run reports, as text to compare.
std::string outputs(LoopDetector& detector) {
  std::ostringstream out;
  out.precision(17);
  for (size_t i = 0; i < keyframes().size(); ++i) {
    const DetectionResult r =
        detector.process(Observation::ofFeatures(keyframes()[i], 0.2 * static_cast<double>(i), i));
    out << i << ":";
    for (const LoopCandidate& c : r.candidates) {
      const Verification& v = c.verification;
      out << " " << c.id << "/" << c.probability << "/" << c.accepted << "/" << v.matches << "/" << v.inliers << "/"
          << v.pose.valid << "/" << v.pose.inliers << "/" << v.pose.translation[0];
    }
    out << "\n";
  }
  return out.str();
}

DetectorParams changed(const std::string& name) {
  const std::string section = name.substr(0, name.find('/'));
  const std::string yaml = section + ":\n  " + name.substr(section.size() + 1) + ": " + kChangedValues.at(name) + "\n";
  return loadDetectorParams(YamlParameterSource::fromString(yaml, name));
}

TEST(Retune, EveryRuntimeParameterHasAValueThatChangesTheOutputs) {
  for (const std::string& name : runtimeParameterNames()) {
    EXPECT_EQ(kChangedValues.count(name), 1u) << name << " is runtime(): give it a value in kChangedValues";
  }
  EXPECT_EQ(kChangedValues.size(), runtimeParameterNames().size()) << "kChangedValues names a fixed parameter";
}

TEST(Retune, EveryRuntimeParameterTakesEffectAsIfTheDetectorHadBeenBuiltWithIt) {
  LoopDetector defaults;
  const std::string default_outputs = outputs(defaults);
  for (const std::string& name : runtimeParameterNames()) {
    if (kChangedValues.count(name) == 0) continue;  // reported by the test above
    const DetectorParams next = changed(name);
    LoopDetector built(next);
    const std::string built_outputs = outputs(built);
    EXPECT_NE(built_outputs, default_outputs) << name << " " << kChangedValues.at(name) << " changes nothing here";

    LoopDetector retuned;
    retuned.retune(next);
    EXPECT_EQ(outputs(retuned), built_outputs) << "retune did not apply " << name;
  }
}

}  // namespace
}  // namespace mild
