// Any binary descriptor, end to end: the pipeline on BRISK's 512 bits and AKAZE's 486 (61 bytes)
// finds the fixture's loop as ORB's 256 do; the map file records the width and a detector of
// another width refuses it by name; keyframes of the wrong width are refused without a trace; a
// node fed a front-end's descriptors takes their width from the first keyframe.
#include <gtest/gtest.h>

#include <filesystem>
#include <random>
#include <set>

#include <opencv2/imgcodecs.hpp>

#include "../common/scratch_folder.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/detector/process_image.hpp"
#include "mild_lcd/detector/robot_team.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "random_descriptors.hpp"
#include "test_images.hpp"

namespace fs = std::filesystem;

namespace mild {
namespace {

const std::string& kFixture = test::kFixtureDir;

using test::fixtureFrames;

DetectorParams paramsFor(const std::string& type) {
  DetectorParams p;
  p.features.type = type;
  p.candidates.exclusion_frames = 8;  // the bench's 40 frames at a stride of 5
  return p;
}

struct FixtureRun {
  Metrics metrics;
  std::set<int> accepted_true, accepted_false;
};

FixtureRun runFixture(LoopDetector& detector) {
  const GroundTruth truth = loadGroundTruth(kFixture + "/gt_loops.txt");
  FixtureRun run;
  std::vector<ScoredPair> reported;
  for (size_t i = 0; i < fixtureFrames().size(); ++i) {
    const DetectionResult r = processImage(detector, fixtureFrames()[i], PixelFormat::kGray, 0.5 * i, i);
    for (const LoopCandidate& c : r.candidates) {
      if (!c.verification.verified) continue;
      reported.push_back({static_cast<int>(i), static_cast<int>(c.id), c.probability});
      if (!c.accepted) continue;
      const std::pair<int, int> pair(static_cast<int>(i), static_cast<int>(c.id));
      (truth.right.count(pair) || truth.dont_care.count(pair) ? run.accepted_true : run.accepted_false)
          .insert(pair.first);
    }
  }
  run.metrics = evaluate(truth, reported, 8);
  return run;
}

class DescriptorWidths : public ::testing::TestWithParam<std::pair<const char*, int>> {};

TEST_P(DescriptorWidths, ThePipelineFindsTheFixtureLoop) {
  const auto [type, bytes] = GetParam();
  LoopDetector detector(paramsFor(type));
  ASSERT_EQ(detector.map().descriptorBytes(), bytes);
  const FixtureRun run = runFixture(detector);
  EXPECT_TRUE(run.accepted_false.empty()) << type << ": " << run.accepted_false.size() << " wrong accepted loops";
  // 13 loop queries (47-59); ORB finds 6 or more (test_loop_detector).
  EXPECT_GE(run.accepted_true.size(), 4u) << type;
  EXPECT_GE(run.metrics.recall_at_100_precision, 0.3) << type;
  RecordProperty(std::string(type) + "_recall_at_100p", std::to_string(run.metrics.recall_at_100_precision));
  // Every stored descriptor has the width, and the index cut it into 16-bit (or 15-16) tables.
  for (KeyframeIndex k = 0; k < detector.map().size(); ++k) {
    for (const Descriptor& d : detector.map().database().descriptors(k)) ASSERT_EQ(d.bytes, bytes);
  }
  EXPECT_EQ(detector.map().database().index().layout().bits(), bytes * 8);
  EXPECT_EQ(detector.map().database().index().layout().count(), (bytes * 8 + 15) / 16);
}

INSTANTIATE_TEST_SUITE_P(Extractors, DescriptorWidths,
                         ::testing::Values(std::make_pair("orb", 32), std::make_pair("brisk", 64),
                                           std::make_pair("akaze", 61)),
                         [](const auto& info) { return std::string(info.param.first); });

class MapFiles : public mild::test::ScratchFolderTest {
 protected:
};

TEST_F(MapFiles, RecordTheWidthAndAreRefusedByADetectorOfAnother) {
  LoopDetector brisk(paramsFor("brisk"));
  for (size_t i = 0; i < 20; ++i) processImage(brisk, fixtureFrames()[i], PixelFormat::kGray, 0.5 * i, i);
  saveMap(brisk.map(), path("brisk.mild"));
  EXPECT_EQ(readMapFile(path("brisk.mild")).descriptor_bytes, 64);

  // Resumed by a BRISK detector: the same answer to the next frame as the one that never stopped.
  LoopDetector resumed(paramsFor("brisk"));
  loadMap(resumed.map(), path("brisk.mild"), true);
  EXPECT_EQ(processImage(resumed, fixtureFrames()[20], PixelFormat::kGray, 10.0).similarity,
            processImage(brisk, fixtureFrames()[20], PixelFormat::kGray, 10.0).similarity);

  // An ORB detector refuses it, naming both widths, and stays as it was (also for a merge).
  LoopDetector orb(paramsFor("orb"));
  processImage(orb, fixtureFrames()[0], PixelFormat::kGray, 0.0);
  for (bool merge : {false, true}) {
    try {
      if (merge) {
        mergeMap(orb.map(), path("brisk.mild"));
      } else {
        loadMap(orb.map(), path("brisk.mild"), false);
      }
      ADD_FAILURE() << "a 64-byte map was loaded into a 32-byte detector";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("64-byte"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("32-byte"), std::string::npos) << e.what();
    }
    EXPECT_EQ(orb.map().size(), 1u);
  }
}

TEST(KeyframeWidths, AKeyframeOfAnotherWidthIsRefusedAndChangesNothing) {
  LoopDetector brisk(paramsFor("brisk"));
  processImage(brisk, fixtureFrames()[0], PixelFormat::kGray, 0.0);
  std::mt19937_64 rng(4);
  Features orb_features;
  orb_features.descriptors = test::randomDescriptors(50, rng, 32);
  orb_features.keypoints.assign(50, cv::KeyPoint(10.0f, 10.0f, 7.0f));
  try {
    brisk.process(Observation::ofFeatures(orb_features, 1.0));
    FAIL() << "32-byte descriptors entered a 64-byte database";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("32 bytes wide; this database holds 64-byte"), std::string::npos) << e.what();
  }
  EXPECT_EQ(brisk.map().size(), 1u);
  EXPECT_EQ(brisk.map().nextId(), 1u);
  // Mixed widths within one keyframe are refused as well.
  Features mixed;
  mixed.descriptors = test::randomDescriptors(3, rng, 64);
  mixed.descriptors.push_back(test::randomDescriptor(rng, 32));
  mixed.keypoints.assign(4, cv::KeyPoint(10.0f, 10.0f, 7.0f));
  EXPECT_THROW(brisk.process(Observation::ofFeatures(mixed, 1.0)), InvalidInput);
  EXPECT_EQ(brisk.map().size(), 1u);
  // The right width goes in.
  Features wide;
  wide.descriptors = test::randomDescriptors(50, rng, 64);
  wide.keypoints.assign(50, cv::KeyPoint(10.0f, 10.0f, 7.0f));
  EXPECT_NO_THROW(brisk.process(Observation::ofFeatures(wide, 1.0)));
  EXPECT_EQ(brisk.map().size(), 2u);
}

// A keyframe without descriptors has no descriptor to judge: it is judged on the width its sender
// declared (a Keyframe's descriptor_bytes: 64 with 0 keypoints used to be stored by a 32-byte node).
TEST(KeyframeWidths, AnEmptyKeyframeIsJudgedOnTheWidthItDeclares) {
  LoopDetector orb(paramsFor("orb"));
  Features empty;
  empty.declared_bytes = 64;
  try {
    orb.process(Observation::ofFeatures(empty, 1.0));
    FAIL() << "an empty 64-byte keyframe entered a 32-byte database";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("64 bytes wide; this database holds 32-byte"), std::string::npos) << e.what();
  }
  EXPECT_EQ(orb.map().size(), 0u);
  EXPECT_EQ(orb.map().nextId(), 0u);
  empty.declared_bytes = 32;
  EXPECT_NO_THROW(orb.process(Observation::ofFeatures(empty, 2.0)))
      << "an empty keyframe of the right width is a keyframe";
  empty.declared_bytes = 0;
  EXPECT_NO_THROW(orb.process(Observation::ofFeatures(empty, 3.0))) << "nothing declared: nothing to judge";
  std::mt19937_64 rng(5);
  Features declared_wrong;  // 32-byte descriptors declared as 64
  declared_wrong.descriptors = test::randomDescriptors(5, rng, 32);
  declared_wrong.keypoints.assign(5, cv::KeyPoint(10.0f, 10.0f, 7.0f));
  declared_wrong.declared_bytes = 64;
  EXPECT_THROW(orb.process(Observation::ofFeatures(declared_wrong, 4.0)), InvalidInput);
  EXPECT_EQ(orb.map().size(), 2u);
}

TEST(KeyframeWidths, ADatabaseOfAFrontEndsOwnWidthTakesKeyframesButRefusesImages) {
  DetectorParams p = paramsFor("orb");
  p.features.descriptor_bytes = 16;  // BRIEF-16 from a front-end
  LoopDetector detector(p);
  EXPECT_EQ(detector.map().descriptorBytes(), 16);
  std::mt19937_64 rng(8);
  for (int k = 0; k < 3; ++k) {
    Features f;
    f.descriptors = test::randomDescriptors(40, rng, 16);
    f.keypoints.assign(40, cv::KeyPoint(10.0f, 10.0f, 7.0f));
    EXPECT_NO_THROW(detector.process(Observation::ofFeatures(f, 1.0 * k)));
  }
  try {
    processImage(detector, fixtureFrames()[0], PixelFormat::kGray, 5.0);
    FAIL() << "an ORB image went into a 16-byte database";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("give it Keyframes"), std::string::npos) << e.what();
  }
  EXPECT_EQ(detector.map().size(), 3u);
}

Features randomFeatures(size_t n, std::mt19937_64& rng, int bytes) {
  Features f;
  f.descriptors = test::randomDescriptors(n, rng, bytes);
  f.keypoints.assign(n, cv::KeyPoint(10.0f, 10.0f, 7.0f));
  return f;
}

// A front-end's own descriptors (OKVIS's BRISK 64 bytes) go into a node left at its defaults: an
// empty map takes the first keyframe's width, and afterwards refuses another, naming the setting.
TEST(FirstKeyframeWidth, AnEmptyTeamTakesItAndRefusesAnotherAfterwardsNamingTheSetting) {
  RobotTeam team(paramsFor("orb"), {"a", "b"});
  team.takeWidthFromFirstKeyframe(true);
  EXPECT_EQ(team.descriptorBytes(), 32);
  std::mt19937_64 rng(11);
  EXPECT_NO_THROW(team.process(Observation::ofFeatures(randomFeatures(60, rng, 64), 0.0, std::nullopt, 1)));
  EXPECT_EQ(team.descriptorBytes(), 64);
  EXPECT_EQ(team.robot(0).map().descriptorBytes(), 64) << "every robot's map takes it together";
  EXPECT_EQ(team.robot(1).map().size(), 1u);
  try {
    team.process(Observation::ofFeatures(randomFeatures(60, rng, 32), 1.0));
    FAIL() << "a 32-byte keyframe entered a map that took 64-byte descriptors";
  } catch (const InvalidInput& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("its first keyframe brought"), std::string::npos) << what;
    EXPECT_NE(what.find("set features/type orb"), std::string::npos) << what;
  }
  EXPECT_EQ(team.keyframes(), 1u);
  // Emptied, it takes the next first keyframe's width again.
  team.reset();
  EXPECT_NO_THROW(team.process(Observation::ofFeatures(randomFeatures(60, rng, 32), 2.0)));
  EXPECT_EQ(team.descriptorBytes(), 32);
}

TEST(FirstKeyframeWidth, IsNotTakenWhenSetOffOrFixedByDescriptorBytes) {
  std::mt19937_64 rng(12);
  RobotTeam off(paramsFor("orb"), {""});  // the default: a node fed images keeps its extractor's width
  EXPECT_THROW(off.process(Observation::ofFeatures(randomFeatures(60, rng, 64), 0.0)), InvalidInput);
  EXPECT_EQ(off.keyframes(), 0u);
  DetectorParams fixed = paramsFor("orb");
  fixed.features.descriptor_bytes = 32;
  RobotTeam pinned(fixed, {""});
  pinned.takeWidthFromFirstKeyframe(true);
  try {
    pinned.process(Observation::ofFeatures(randomFeatures(60, rng, 64), 0.0));
    FAIL() << "features/descriptor_bytes 32 took a 64-byte keyframe";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("features/descriptor_bytes 32"), std::string::npos) << e.what();
  }
  EXPECT_EQ(pinned.descriptorBytes(), 32);
}

TEST(FirstKeyframeWidth, AMapThatHoldsAKeyframeKeepsItsWidth) {
  std::mt19937_64 rng(13);
  RobotTeam team(paramsFor("orb"), {""});
  team.takeWidthFromFirstKeyframe(true);
  team.process(Observation::ofFeatures(randomFeatures(60, rng, 32), 0.0));
  EXPECT_FALSE(team.takeWidth(64));
  EXPECT_THROW(team.process(Observation::ofFeatures(randomFeatures(60, rng, 64), 1.0)), InvalidInput);
  EXPECT_EQ(team.descriptorBytes(), 32);
  EXPECT_EQ(team.keyframes(), 1u);
}

TEST_F(MapFiles, ARefusedMapsMessageNamesTheSettingThatLoadsIt) {
  LoopDetector brisk(paramsFor("brisk"));
  for (size_t i = 0; i < 3; ++i) processImage(brisk, fixtureFrames()[i], PixelFormat::kGray, 0.5 * i, i);
  saveMap(brisk.map(), path("brisk.mild"));
  LoopDetector orb(paramsFor("orb"));
  try {
    loadMap(orb.map(), path("brisk.mild"), false);
    FAIL() << "a 64-byte map was loaded into a 32-byte detector";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("set features/type brisk to load it"), std::string::npos) << e.what();
  }
  // A map of a width no extractor has names the width itself.
  DetectorParams p16 = paramsFor("orb");
  p16.features.descriptor_bytes = 16;
  LoopDetector narrow(p16);
  std::mt19937_64 rng(14);
  narrow.process(Observation::ofFeatures(randomFeatures(40, rng, 16), 0.0));
  saveMap(narrow.map(), path("narrow.mild"));
  try {
    loadMap(orb.map(), path("narrow.mild"), false);
    FAIL() << "a 16-byte map was loaded into a 32-byte detector";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("set features/descriptor_bytes 16 to load it"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace mild
