// The ROS layer's parts that need no master: node settings, where maps may go, the keyframe
// worker's counting, the debug image cache, compressed-image headers.

#include <gtest/gtest.h>

#include <unistd.h>

#include <atomic>
#include <cmath>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <thread>

#include <sensor_msgs/image_encodings.h>
#include <boost/make_shared.hpp>
#include <opencv2/imgcodecs.hpp>

#include "../common/scratch_folder.hpp"
#include "../core/error_text.hpp"
#include "../core/fixture_params.hpp"
#include "../core/test_images.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "mild_lcd/ros/conversions.hpp"
#include "mild_lcd/ros/database_store.hpp"
#include "mild_lcd/ros/debug_image.hpp"
#include "mild_lcd/ros/keyframe_worker.hpp"
#include "mild_lcd/ros/node_settings.hpp"
#include "mild_lcd/ros/periodic_task.hpp"
#include "mild_lcd/ros/tuning_config.hpp"

namespace fs = std::filesystem;

namespace mild_lcd {
namespace {

using mild::YamlParameterSource;
using mild::test::errorOf;
using mild::test::fixtureParams;

NodeSettings settingsFrom(const std::string& yaml, const std::string& default_dir = "/tmp/mild_default") {
  return NodeSettings::load(YamlParameterSource::fromString(yaml), default_dir);
}

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

// BRISK and AKAZE on images as large as ~max_image_pixels allows can hold the worker for minutes:
// the node says so at start-up, unless the bound keeps images small or the input is features.
TEST(NodeSettings, WarnsOfCostlyExtractionOnLargeImages) {
  EXPECT_EQ(extractionCostWarning(settingsFrom(""), "orb"), "");
  EXPECT_NE(extractionCostWarning(settingsFrom(""), "akaze").find("~max_image_pixels (16777216)"), std::string::npos);
  EXPECT_NE(extractionCostWarning(settingsFrom(""), "brisk"), "");
  EXPECT_EQ(extractionCostWarning(settingsFrom("max_image_pixels: 4194304\n"), "akaze"), "");
  EXPECT_EQ(extractionCostWarning(settingsFrom("use_image_input: false\n"), "akaze"), "");
}

TEST(NodeSettings, TheReadmeTableIsTheDeclaration) {
  std::ifstream in(std::string(MILD_SOURCE_DIR) + "/README.md");
  const std::string readme((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(readme.find(nodeSettingsMarkdown()), std::string::npos)
      << "README.md's node parameter table is out of date; it must read exactly:\n"
      << nodeSettingsMarkdown();
}

TEST(NodeSettings, TheDatabaseFolderDefaultsToThePathsFolderOrRosHome) {
  EXPECT_EQ(settingsFrom("").database_dir, "/tmp/mild_default");
  EXPECT_EQ(settingsFrom("database_path: /data/maps/site.db\n").database_dir, "/data/maps");
  EXPECT_EQ(settingsFrom("database_path: site.db\n").database_dir, "/tmp/mild_default");
  EXPECT_EQ(settingsFrom("database_dir: /srv/maps\ndatabase_path: site.db\n").database_dir, "/srv/maps");
  EXPECT_FALSE(nodeSettingDocs().empty());
}

class Store : public mild::test::ScratchFolderTest {
 protected:
  static std::unique_ptr<mild::LoopDetector> detector(size_t keyframes) {
    mild::DetectorParams p;
    p.verification.enabled = false;
    auto d = std::make_unique<mild::LoopDetector>(p);
    cv::RNG rng(3);
    for (size_t k = 0; k < keyframes; ++k) {
      mild::Features f;
      for (int i = 0; i < 200; ++i) {
        mild::Descriptor desc;  // ORB's 32 bytes
        for (int w = 0; w < desc.numWords(); ++w)
          desc.words[w] = (static_cast<uint64_t>(rng.next()) << 32) | rng.next();
        f.descriptors.push_back(desc);
        f.keypoints.emplace_back(1.0f * i, 1.0f * k, 7.0f);
      }
      d->process(std::move(f), 1.0 * k);
    }
    return d;
  }
  NodeSettings settings(const std::string& extra = "") const {
    return settingsFrom("database_dir: " + dir_.string() + "\n" + extra);
  }
};

// Live tuning never waits for the detector (a merge or a save may hold it for seconds; the
// dynamic_reconfigure server shares the nodelet's callback queue): a retune that finds the lock
// held waits for its holder, and is in force before anyone next reads the parameters.
TEST(SharedDetectorRetune, NeverWaitsForTheDetectorAndHoldsBeforeItIsNextUsed) {
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>()));
  mild::DetectorParams next = shared.team->params();
  ASSERT_NE(next.candidates.max_candidates, 1);
  next.candidates.max_candidates = 1;
  {
    std::unique_lock<std::mutex> merging(shared.mutex);  // someone holds the detector
    shared.requestRetune(next);                          // returns without waiting for it
    EXPECT_TRUE(shared.retunePending());
    EXPECT_NE(shared.team->params().candidates.max_candidates, 1);
  }
  {
    const auto lock = shared.lock();  // the next user: the keyframe worker, a service
    EXPECT_EQ(shared.team->params().candidates.max_candidates, 1);
  }
  EXPECT_FALSE(shared.retunePending());
  next.candidates.max_candidates = 2;
  shared.requestRetune(next);  // the detector is free: applied at once
  EXPECT_FALSE(shared.retunePending());
  EXPECT_EQ(shared.team->params().candidates.max_candidates, 2);
  EXPECT_EQ(shared.team->retunes(), 2u);
}

// Any failure to load at start-up (here a map over ~max_database_mb: a CapacityError, not bad
// input) leaves the file as it is and keeps save_on_shutdown from writing over it.
TEST_F(Store, AnyStartUpLoadFailureLeavesTheMapAndDisablesSaving) {
  SharedDetector original;
  original.setTeam(std::make_unique<mild::RobotTeam>(detector(120)));
  mild::saveDetector(original.robot(0), (dir_ / "map.db").string());
  const auto size = fs::file_size(dir_ / "map.db");
  ASSERT_GT(size, 1u << 20);

  DatabaseStore store(
      settings("database_path: map.db\nload_on_start: true\nsave_on_shutdown: true\nmax_database_mb: 1\n"));
  SharedDetector running;
  running.setTeam(std::make_unique<mild::RobotTeam>(detector(0)));
  const std::string error = errorOf([&] { store.loadOnStart(running); });
  EXPECT_NE(error.find("allowed"), std::string::npos) << error;
  EXPECT_FALSE(running.failure[0].empty()) << "keyframes are refused, saying why";
  EXPECT_NE(running.failure[0].find("left untouched"), std::string::npos) << running.failure[0];
  EXPECT_NE(store.saveOnShutdown(running).find("not saving"), std::string::npos);
  EXPECT_THROW(store.save(running, ""), mild::InvalidInput) << "nor through the service";
  // Merging into the empty stand-in would let a later save replace the map that failed.
  mild::saveDetector(*detector(2), (dir_ / "small.db").string());
  const std::string merge_error = errorOf([&] { store.merge(running, "small.db"); });
  EXPECT_NE(merge_error.find("without merge replaces it"), std::string::npos) << merge_error;
  EXPECT_EQ(running.robot(0).size(), 0u);
  EXPECT_EQ(fs::file_size(dir_ / "map.db"), size) << "the map is untouched";
  EXPECT_EQ(mild::readDetectorFile((dir_ / "map.db").string()).records.size(), 120u);
}

TEST_F(Store, AMissingMapStartsEmptyAndIsSavedOnShutdown) {
  DatabaseStore store(settings("database_path: new.db\nload_on_start: true\nsave_on_shutdown: true\n"));
  SharedDetector running;
  running.setTeam(std::make_unique<mild::RobotTeam>(detector(3)));
  EXPECT_NE(store.loadOnStart(running).find("does not exist yet"), std::string::npos);
  EXPECT_NE(store.saveOnShutdown(running).find("saved 3 keyframes"), std::string::npos);
  EXPECT_EQ(mild::readDetectorFile((dir_ / "new.db").string()).records.size(), 3u);
}

// ~autosave_period: with save_on_shutdown, the map is written when it changed since it was last
// written to ~database_path (by any save), and never after a failed start-up load.
TEST_F(Store, AutosaveWritesTheMapOnlyWhenItChanged) {
  DatabaseStore store(settings("database_path: auto.db\nsave_on_shutdown: true\n"));
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(detector(3)));
  EXPECT_EQ(store.autosave(shared), "") << "nothing learnt since start-up";
  EXPECT_FALSE(fs::exists(dir_ / "auto.db"));
  ++shared.changes;  // as the worker does after each keyframe
  EXPECT_NE(store.autosave(shared).find("saved 3 keyframes"), std::string::npos);
  EXPECT_EQ(mild::readDetectorFile((dir_ / "auto.db").string()).records.size(), 3u);
  EXPECT_EQ(store.autosave(shared), "") << "unchanged since";
  ++shared.changes;
  store.save(shared, "auto.db");  // the service, to ~database_path
  EXPECT_EQ(store.autosave(shared), "") << "the service's save counts";
  ++shared.changes;
  store.save(shared, "elsewhere.db");
  EXPECT_NE(store.autosave(shared), "") << "a save elsewhere does not";

  DatabaseStore without(settings("database_path: off.db\n"));
  EXPECT_EQ(without.autosave(shared), "") << "only with save_on_shutdown";
  EXPECT_FALSE(fs::exists(dir_ / "off.db"));
}

TEST(PeriodicTask, RunsEveryPeriodUntilDestroyed) {
  std::atomic<int> runs{0};
  {
    PeriodicTask task(std::chrono::milliseconds(10), [&] { ++runs; });
    while (runs < 3) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const int after = runs;
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(runs, after) << "no run after destruction";
}

TEST_F(Store, ServicesSaveAndLoadInsideTheFolderOnly) {
  DatabaseStore store(settings());
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(detector(4)));
  std::ofstream(dir_.parent_path() / "victim.txt") << "precious";
  for (const std::string& bad :
       {std::string("../victim.txt"), (dir_.parent_path() / "victim.txt").string(), std::string("")}) {
    EXPECT_THROW(store.save(shared, bad), mild::InvalidInput) << bad;
  }
  EXPECT_EQ(store.save(shared, "robot/one.db"), "saved 4 keyframes to " + (dir_ / "robot/one.db").string());
  SharedDetector other;
  other.setTeam(std::make_unique<mild::RobotTeam>(detector(0)));
  EXPECT_EQ(store.load(other, (dir_ / "robot/one.db").string(), false).keyframes, 4u);
  EXPECT_EQ(other.robot(0).size(), 4u);
  EXPECT_THROW(DatabaseStore(settings("database_path: /etc/passwd\n")), mild::InvalidInput)
      << "~database_path outside ~database_dir stops the node at start-up";
}

// --- the worker

// Polls `done` until it holds; false after `timeout`, so that a broken worker fails a test rather
// than hanging it.
bool eventually(const std::function<bool()>& done, std::chrono::milliseconds timeout = std::chrono::seconds(20)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return true;
}

sensor_msgs::ImagePtr image(int width, int height, double stamp, const std::string& encoding = "mono8") {
  auto msg = boost::make_shared<sensor_msgs::Image>();
  msg->header.stamp = ros::Time(stamp);
  msg->width = static_cast<uint32_t>(width);
  msg->height = static_cast<uint32_t>(height);
  msg->encoding = encoding;
  msg->step = static_cast<uint32_t>(width);
  msg->data.resize(static_cast<size_t>(width) * static_cast<size_t>(height));
  cv::RNG rng(static_cast<uint64_t>(stamp * 10) + 1);
  for (auto& b : msg->data) b = static_cast<uint8_t>(rng.uniform(0, 256));
  return msg;
}

TEST(Worker, CountsEveryKeyframeAnsweredRejectedOrDiscarded) {
  SharedDetector shared;
  mild::DetectorParams p;
  p.verification.enabled = false;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(p)));
  std::atomic<int> published{0};
  KeyframeWorker::Hooks hooks;
  hooks.publish = [&](const ProcessedKeyframe&) {
    ++published;
    throw std::runtime_error("a publisher that fails");  // not the keyframe's fault
  };
  KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{1000 * 1000, 10000}, hooks);
  worker.start();
  worker.push(imageInput(image(200, 150, 1.0)));
  worker.push(imageInput(image(1, 1, 2.0)));           // thinner than ORB's border: stored, no features
  worker.push(imageInput(image(8, 8, 3.0, "32FC1")));  // unusable encoding
  worker.push(imageInput(image(2000, 1000, 4.0)));     // over max_image_pixels
  worker.waitIdle();
  const WorkerCounters c = worker.counters();
  EXPECT_EQ(c.processed, 2u) << "the thin image is a keyframe, answered";
  EXPECT_EQ(c.rejected, 2u);
  EXPECT_EQ(published.load(), 2);
  EXPECT_EQ(shared.robot(0).size(), 2u);
}

TEST(Worker, StoppingDiscardsWhatWaitsAndCountsIt) {
  for (const bool extraction_thread : {false, true}) {
    SCOPED_TRACE(extraction_thread ? "extraction thread" : "one thread");
    SharedDetector shared;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>()));
    std::mutex gate;
    std::unique_lock<std::mutex> hold(gate);  // the first keyframe waits here until we let it go
    std::atomic<bool> publishing{false};
    KeyframeWorker::Hooks hooks;
    hooks.publish = [&](const ProcessedKeyframe&) {
      publishing = true;
      std::lock_guard<std::mutex> wait(gate);
    };
    KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{1000 * 1000, 10000}, hooks, extraction_thread);
    worker.start();
    for (int i = 0; i < 10; ++i) worker.push(imageInput(image(160, 120, i)));
    EXPECT_TRUE(eventually([&] { return publishing.load(); }));
    std::thread stopper([&] { worker.stop(); });
    EXPECT_TRUE(eventually([&] { return worker.counters().discarded > 0; }));
    hold.unlock();
    stopper.join();
    const WorkerCounters c = worker.counters();
    EXPECT_EQ(c.processed + c.discarded + c.dropped + c.rejected, 10u) << "every keyframe accounted for";
    EXPECT_EQ(c.processed, 1u);
  }
}

TEST(DebugImages, TheCacheIsBoundedInBytes) {
  DebugImageCache cache(1000, 4u << 20);
  for (uint64_t id = 0; id < 20; ++id)
    cache.remember(id, cv::Mat(2000, 2000, CV_8UC1, cv::Scalar(1)), mild::PixelFormat::kGray);
  EXPECT_LE(cache.bytes(), 4u << 20);
  EXPECT_FALSE(cache.find(19).empty()) << "the newest stays";
  EXPECT_TRUE(cache.find(0).empty());
  cache.remember(50, cv::Mat(1, 1, CV_8UC1, cv::Scalar(9)), mild::PixelFormat::kGray);  // no half of one pixel
  EXPECT_FALSE(cache.find(50).empty());
}

TEST(DebugImages, KeepTheDecodedChannelOrder) {
  cv::Mat rgb(40, 40, CV_8UC3, cv::Scalar(255, 0, 0));  // pure red as RGB
  DebugImageCache cache(10, 1u << 20);
  cache.remember(1, rgb, mild::PixelFormat::kRgb);
  cache.remember(2, rgb, mild::PixelFormat::kBgr);  // the same bytes read as BGR: blue
  EXPECT_NE(cache.find(1).at<uint8_t>(5, 5), cache.find(2).at<uint8_t>(5, 5));
  EXPECT_EQ(cache.find(1).at<uint8_t>(5, 5), 76) << "red's luma (0.299 x 255)";
}

// The picture shows what it says: query left and candidate right at half resolution, the inlier
// drawn as a green line from the query's keypoint to the candidate's, unmatched keypoints as grey
// circles, and a label; without a candidate, the query alone labelled in red.
TEST(DebugImages, DrawTheInliersWhereTheKeypointsAre) {
  const cv::Mat query(200, 320, CV_8UC1, cv::Scalar(0));
  const cv::Mat candidate(100, 160, CV_8UC1, cv::Scalar(0));  // cached at half resolution, as the cache keeps it
  const cv::Mat query_half(100, 160, CV_8UC1, cv::Scalar(0));
  const std::vector<cv::KeyPoint> query_kps = {cv::KeyPoint(80, 120, 8), cv::KeyPoint(240, 40, 8)};
  const std::vector<cv::KeyPoint> candidate_kps = {cv::KeyPoint(200, 160, 8)};
  mild::DetectionResult result;
  result.query_id = 7;
  mild::LoopCandidate best;
  best.id = 3;
  best.verification.verified = true;
  best.verification.inliers = 1;
  best.verification.inlier_matches = {mild::FeatureMatch{0, 0, 10}};
  result.candidates.push_back(best);
  const cv::Mat canvas = drawDebugImage(query_half, query_kps, candidate, candidate_kps, result);
  ASSERT_EQ(canvas.type(), CV_8UC3);
  ASSERT_EQ(canvas.size(), cv::Size(320, 100));
  const auto green = [&](cv::Point p) {
    const cv::Vec3b c = canvas.at<cv::Vec3b>(p);
    return c[1] > 100 && c[0] < c[1] / 2 && c[2] < c[1] / 2;
  };
  // Query keypoint 0 is at (40, 60) in the half image, candidate keypoint 0 at (100, 80) + 160.
  const cv::Point from(40, 60), to(160 + 100, 80);
  const cv::Point middle((from.x + to.x) / 2, (from.y + to.y) / 2);
  int on_line = 0;
  for (int dy = -1; dy <= 1; ++dy) on_line += green(middle + cv::Point(0, dy)) ? 1 : 0;
  EXPECT_GT(on_line, 0) << "the inlier's line passes between the two keypoints";
  EXPECT_FALSE(green(cv::Point(40, 90))) << "nothing green away from the match";
  // The unmatched query keypoint (120, 20) is drawn as a grey circle of its (halved) size.
  bool grey = false;
  for (int y = 14; y <= 26 && !grey; ++y) {
    for (int x = 114; x <= 126 && !grey; ++x) {
      const cv::Vec3b c = canvas.at<cv::Vec3b>(y, x);
      grey = c[0] > 40 && c[0] == c[1] && c[1] == c[2];
    }
  }
  EXPECT_TRUE(grey) << "the unmatched keypoint is drawn where it is";
  EXPECT_EQ(canvas.at<cv::Vec3b>(95, 80), cv::Vec3b(0, 0, 0)) << "the images themselves are untouched elsewhere";
  // The label (green: verified) is written in the top-left corner.
  int label = 0;
  for (int y = 2; y < 18; ++y) {
    for (int x = 5; x < 150; ++x) label += green(cv::Point(x, y)) ? 1 : 0;
  }
  EXPECT_GT(label, 20) << "a green label for a verified loop";

  mild::DetectionResult none;
  const cv::Mat alone = drawDebugImage(query_half, query_kps, cv::Mat(), {}, none);
  ASSERT_EQ(alone.size(), cv::Size(160, 100)) << "the query alone";
  int red = 0;
  for (int y = 2; y < 18; ++y) {
    for (int x = 5; x < 150; ++x) {
      const cv::Vec3b c = alone.at<cv::Vec3b>(y, x);
      red += c[2] > 200 && c[0] < 50 && c[1] < 50 ? 1 : 0;
    }
  }
  EXPECT_GT(red, 20) << "\"no candidate\" in red";
}

// A few hundred bytes of JPEG whose header claims 20000 x 20000 pixels are refused on the header.
TEST(CompressedImages, AreJudgedByTheirHeaderBeforeDecoding) {
  std::vector<uint8_t> jpeg;
  cv::imencode(".jpg", cv::Mat(8, 8, CV_8UC1, cv::Scalar(100)), jpeg);
  ASSERT_EQ(compressedImageSize(jpeg), cv::Size(8, 8));
  for (size_t i = 2; i + 9 < jpeg.size(); ++i) {  // rewrite the frame header's size
    if (jpeg[i] == 0xFF && jpeg[i + 1] == 0xC0) {
      jpeg[i + 5] = 20000 >> 8, jpeg[i + 6] = 20000 & 0xFF, jpeg[i + 7] = 20000 >> 8, jpeg[i + 8] = 20000 & 0xFF;
    }
  }
  ASSERT_EQ(compressedImageSize(jpeg), cv::Size(20000, 20000));
  sensor_msgs::CompressedImage msg;
  msg.format = "jpeg";
  msg.data = jpeg;
  const std::string error = errorOf([&] { imageFromMsg(msg, 4096u * 4096u); });
  EXPECT_NE(error.find("20000 x 20000"), std::string::npos) << error;

  std::vector<uint8_t> png;
  cv::imencode(".png", cv::Mat(30, 50, CV_8UC1, cv::Scalar(1)), png);
  EXPECT_EQ(compressedImageSize(png), cv::Size(50, 30));
  msg.data = png;
  EXPECT_EQ(imageFromMsg(msg, 50 * 30).image.size(), cv::Size(50, 30));
  EXPECT_THROW(imageFromMsg(msg, 50 * 30 - 1), mild::InvalidInput);
}

// Formats whose header this node does not read are refused before any decoder sees them: OpenCV's
// TIFF and WebP decoders allocate for the size their header claims (593 bytes of TIFF may claim
// 20000 x 20000 pixels).
TEST(CompressedImages, OnlyJpegAndPngAreDecoded) {
  const cv::Mat small(8, 8, CV_8UC3, cv::Scalar(10, 20, 30));
  sensor_msgs::CompressedImage msg;
  for (const std::string ext : {".tiff", ".webp", ".bmp", ".ppm"}) {
    if (!cv::haveImageWriter(ext)) continue;
    ASSERT_TRUE(cv::imencode(ext, small, msg.data)) << ext;
    msg.format = ext.substr(1);
    const std::string error = errorOf([&] { imageFromMsg(msg); });
    EXPECT_NE(error.find("not a JPEG or PNG"), std::string::npos) << ext << ": " << error;
    EXPECT_NE(errorOf([&] { checkedInputBytes(msg, InputLimits{}); }), "") << ext;
  }
  ASSERT_TRUE(cv::imencode(".jpg", small, msg.data));
  EXPECT_EQ(imageFromMsg(msg).image.size(), small.size());
  // And at most 4 bytes per pixel of ~max_image_pixels, whatever the header says.
  msg.data.resize(4 * 1000 + 1, 0);
  EXPECT_NE(errorOf([&] { imageFromMsg(msg, 1000); }).find("larger than 4000"), std::string::npos);
}

// A raw image's data is exactly step x height, and its step cannot make it larger than
// ~max_image_pixels pixels of its encoding: eight 320 x 240 images carrying 250 MB each took the
// node from 79 MB to 2.3 GB.
TEST(InputBounds, AnImagesDataIsExactlyStepTimesHeightAndBoundedInBytes) {
  auto msg = image(320, 240, 1.0);
  const InputLimits limits{640 * 480, 10000};
  EXPECT_GE(checkedInputBytes(*msg, limits), 320u * 240u);
  EXPECT_EQ(imageFromMsg(*msg, limits.max_image_pixels).image.size(), cv::Size(320, 240));
  msg->data.resize(320 * 240 + 1);  // one byte more than declared
  EXPECT_NE(errorOf([&] { imageFromMsg(*msg, limits.max_image_pixels); }).find("exactly step x height"),
            std::string::npos);
  EXPECT_NE(errorOf([&] { checkedInputBytes(*msg, limits); }), "");
  msg->step = 320 * 1000;  // a step a thousand rows wide, and data to match: 76.8 MB
  msg->data.assign(static_cast<size_t>(msg->step) * msg->height, 0);
  EXPECT_NE(errorOf([&] { checkedInputBytes(*msg, limits); }).find("more than ~max_image_pixels"), std::string::npos);
  msg = image(320, 240, 2.0);
  msg->header.frame_id.assign(100 * 1024, 'x');  // everything besides the pixels is small
  EXPECT_NE(errorOf([&] { checkedInputBytes(*msg, limits); }).find("besides its payload"), std::string::npos);
}

TEST(InputBounds, AKeyframeHasAtMostMaxKeyframeFeaturesAndSmallExtras) {
  const InputLimits limits{kDefaultMaxImagePixels, 100};
  mild_lcd::Keyframe kf;
  kf.keypoints.resize(100);
  kf.descriptors.assign(100 * 32, 1);
  kf.depths.assign(100, 1.0f);
  EXPECT_GE(checkedInputBytes(kf, limits), 100u * (24 + 32 + 4));
  kf.keypoints.resize(101);
  kf.descriptors.assign(101 * 32, 1);
  EXPECT_NE(errorOf([&] { checkedInputBytes(kf, limits); }).find("~max_keyframe_features (100)"), std::string::npos);
  kf.keypoints.resize(1);
  kf.descriptors.assign(101 * 64 + 1, 1);  // descriptors of no keypoints
  EXPECT_NE(errorOf([&] { checkedInputBytes(kf, limits); }), "");
  kf.descriptors.assign(32, 1);
  kf.depths.clear();
  kf.camera_info.D.assign(1000000, 0.0);  // 8 MB of "distortion"
  EXPECT_NE(errorOf([&] { checkedInputBytes(kf, limits); }).find("besides its payload"), std::string::npos);
}

// Oversize messages are rejected (counted) as they are pushed, so they are released at once; the
// queue holds at most queue_bytes of messages, dropping (counting) the oldest to make room.
// With the extraction thread, one keyframe more is out of the queue: extracted, waiting for the
// detector (the hand-off), where no drop reaches it.
TEST(Worker, TheQueueIsBoundedInBytesAndOversizeInputsAreRejectedAsTheyArrive) {
  for (const bool extraction_thread : {false, true}) {
    SCOPED_TRACE(extraction_thread ? "extraction thread" : "one thread");
    SharedDetector shared;
    mild::DetectorParams p;
    p.verification.enabled = false;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(p)));
    std::mutex gate;
    std::unique_lock<std::mutex> hold(gate);  // the worker waits in its first publish until released
    std::atomic<int> staged{0};
    KeyframeWorker::Hooks hooks;
    hooks.publish = [&](const ProcessedKeyframe&) { std::lock_guard<std::mutex> wait(gate); };
    hooks.staged = [&](const std_msgs::Header&, bool) { ++staged; };
    KeyframeWorker worker(shared, 100, 200 * 1000, InputLimits{2000 * 2000, 10000}, hooks, extraction_thread);
    worker.start();
    EXPECT_EQ(worker.push(imageInput(image(200, 150, 1.0))), KeyframeWorker::Pushed::kQueued);
    while (worker.counters().queued > 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));  // in progress
    auto oversize = image(320, 240, 2.0);
    oversize->data.resize(oversize->data.size() * 2);
    EXPECT_EQ(worker.push(imageInput(oversize)), KeyframeWorker::Pushed::kRejected);
    EXPECT_EQ(oversize.use_count(), 1) << "not kept by the worker";
    EXPECT_EQ(worker.push(imageInput(image(500, 500, 3.0))), KeyframeWorker::Pushed::kRejected)
        << "larger than the whole queue";
    for (int i = 0; i < 5; ++i) worker.push(imageInput(image(200, 150, 4.0 + i)));  // 30 KB each
    WorkerCounters c = worker.counters();
    EXPECT_LE(c.queued_bytes, 200u * 1000u);
    EXPECT_EQ(c.rejected, 2u);
    const int out_of_queue = extraction_thread ? 2 : 1;  // the first, and the next one extracted
    EXPECT_TRUE(eventually([&] { return staged.load() >= out_of_queue; }));
    for (int i = 0; i < 5; ++i) worker.push(imageInput(image(300, 300, 10.0 + i)));  // 90 KB each
    c = worker.counters();
    EXPECT_LE(c.queued_bytes, 200u * 1000u);
    EXPECT_EQ(c.queued, 2u) << "two of 90 KB fit in 200 KB";
    EXPECT_EQ(c.dropped, extraction_thread ? 7u : 8u);
    hold.unlock();
    worker.waitIdle();
    c = worker.counters();
    EXPECT_EQ(c.processed + c.dropped + c.rejected, 13u) << "every keyframe accounted for";
    EXPECT_EQ(c.processed, extraction_thread ? 4u : 3u);
  }
}

// sparse_match by id bounds the stored keyframes as it bounds a request's descriptors: a map loaded
// from a file may hold keyframes of any size (two of 20,000 and 100,000 features held the service
// thread for 17 and 68 s).
TEST(SparseMatchRequests, StoredKeyframesAreBoundedByMaxMatchFeaturesToo) {
  const auto keyframe = [](size_t n) {
    mild::Features f;
    cv::RNG rng(static_cast<uint64_t>(n));
    for (size_t i = 0; i < n; ++i) {
      mild::Descriptor d;
      for (int w = 0; w < d.numWords(); ++w) d.words[w] = (static_cast<uint64_t>(rng.next()) << 32) | rng.next();
      f.descriptors.push_back(d);
      f.keypoints.emplace_back(static_cast<float>(rng.uniform(0, 640)), static_cast<float>(rng.uniform(0, 480)), 7.0f);
    }
    return f;
  };
  const StoredFeatures stored = [&](uint64_t id) -> std::optional<mild::Features> { return keyframe(id); };
  const mild::GeometricVerifier verifier(mild::VerificationParams{});
  mild_lcd::SparseMatch::Request request;
  request.query_id = 20000;  // the stand-in's id is its feature count
  request.train_id = 300;
  auto response = sparseMatch(request, stored, verifier, 10000);
  EXPECT_FALSE(response.success);
  EXPECT_NE(response.message.find("query keyframe 20000 has 20000 features, more than ~max_match_features (10000)"),
            std::string::npos)
      << response.message;
  std::swap(request.query_id, request.train_id);
  response = sparseMatch(request, stored, verifier, 10000);
  EXPECT_FALSE(response.success);
  EXPECT_NE(response.message.find("train keyframe 20000"), std::string::npos) << response.message;
  request.query_id = 200;
  request.train_id = 300;
  response = sparseMatch(request, stored, verifier, 300);
  EXPECT_TRUE(response.success) << response.message;
}

// A Keyframe message's descriptor_bytes reaches the detector even with no keypoints.
TEST(Conversions, AnEmptyKeyframeCarriesItsDeclaredWidth) {
  mild_lcd::Keyframe kf;
  kf.descriptor_bytes = 64;
  EXPECT_EQ(featuresFromMsg(kf).declared_bytes, 64);
  kf.descriptor_bytes = 0;
  EXPECT_EQ(featuresFromMsg(kf).declared_bytes, 32) << "0 means 32";
  kf.descriptor_bytes = 64;
  mild::LoopDetector orb;
  EXPECT_THROW(orb.process(featuresFromMsg(kf), 1.0), mild::InvalidInput);
  EXPECT_EQ(orb.size(), 0u);
}

TEST(Conversions, StampsOutsideRosTimeAreClamped) {
  EXPECT_EQ(stampOf(-5.0), ros::Time(0, 0));
  EXPECT_EQ(stampOf(1e12), ros::Time(4294967295u, 0));
  EXPECT_EQ(stampOf(12.5), ros::Time(12.5));
}

TEST(Conversions, AStepThatSplitsASampleIsRefusedNotThrownByOpenCv) {
  // Found by fuzz_keyframe_message: mono16 rows of an odd number of bytes made cv::Mat throw.
  sensor_msgs::Image msg;
  msg.encoding = "mono16";
  msg.width = 4;
  msg.height = 2;
  msg.step = 9;
  msg.data.assign(18, 0);
  try {
    imageFromMsg(msg, 1u << 24);
    FAIL() << "an odd mono16 step was accepted";
  } catch (const mild::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("multiple of the 2-byte sample"), std::string::npos) << e.what();
  }
  msg.step = 10;
  msg.data.assign(20, 0);
  EXPECT_EQ(imageFromMsg(msg, 1u << 24).image.rows, 2) << "an even padded step is fine";
}

TEST(Conversions, TheRelativePoseIsPublishedAsAUnitQuaternionAndDirection) {
  mild::DetectionResult result;
  mild::LoopCandidate posed, plain;
  const double a = 30.0 * M_PI / 180.0;  // about the optical y axis
  posed.verification.pose.valid = true;
  posed.verification.pose.rotation = cv::Matx33d(std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a));
  posed.verification.pose.translation = cv::Vec3d(0.6, 0.0, 0.8);
  posed.verification.pose.inliers = 42;
  plain.verification.fit_skipped = true;
  plain.verification.matches = 17;
  result.candidates = {posed, plain};
  const LoopClosure msg = loopClosureToMsg(result, std_msgs::Header(), 10);
  ASSERT_EQ(msg.candidates.size(), 2u);
  EXPECT_FALSE(msg.candidates[0].fit_skipped);
  EXPECT_TRUE(msg.candidates[1].fit_skipped) << "a candidate not fitted says so, not only 'not verified'";
  EXPECT_EQ(msg.candidates[1].matches, 17);
  const auto& q = msg.candidates[0].relative_rotation;
  EXPECT_TRUE(msg.candidates[0].has_relative_pose);
  EXPECT_NEAR(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w, 1.0, 1e-12);
  EXPECT_NEAR(q.y, std::sin(a / 2), 1e-12);
  EXPECT_NEAR(q.w, std::cos(a / 2), 1e-12);
  EXPECT_DOUBLE_EQ(msg.candidates[0].relative_translation.x, 0.6);
  EXPECT_DOUBLE_EQ(msg.candidates[0].relative_translation.z, 0.8);
  EXPECT_EQ(msg.candidates[0].pose_inliers, 42);
  EXPECT_FALSE(msg.candidates[1].has_relative_pose);
  EXPECT_EQ(msg.candidates[1].relative_rotation.w, 1.0) << "identity, not an invalid zero quaternion";
}

TEST(Conversions, AKeyframesCameraInfoAndDepthsReachTheCore) {
  mild_lcd::Keyframe msg;
  msg.keypoints.resize(2);
  msg.descriptors.assign(2 * mild::kOrbDescriptorBytes, 0x5A);
  msg.camera_info.K = {256.0, 0.0, 159.5, 0.0, 250.0, 119.5, 0.0, 0.0, 1.0};
  msg.depths = {1.5f, std::nanf("")};
  const mild::Features f = featuresFromMsg(msg);
  EXPECT_EQ(f.camera, (mild::CameraIntrinsics{256.0, 250.0, 159.5, 119.5}));
  ASSERT_EQ(f.depths.size(), 2u);
  EXPECT_EQ(f.depths[0], 1.5f);

  msg.depths.push_back(2.0f);  // three depths for two keypoints: refused by the detector, unchanged
  mild::LoopDetector detector;
  EXPECT_THROW(detector.process(featuresFromMsg(msg), 1.0), mild::InvalidInput);
  EXPECT_EQ(detector.size(), 0u);
  msg.depths.clear();
  msg.camera_info.K = {};  // all zero: unknown, not an error
  EXPECT_FALSE(featuresFromMsg(msg).camera.known());
  msg.camera_info.K = {0.0, 0.0, 159.5, 0.0, 250.0, 119.5, 0.0, 0.0, 1.0};  // fx missing
  EXPECT_THROW(featuresFromMsg(msg), mild::InvalidInput);
  sensor_msgs::CameraInfo info;
  info.K = {256.0, 0.0, std::numeric_limits<double>::infinity(), 0.0, 256.0, 119.5, 0.0, 0.0, 1.0};
  EXPECT_THROW(intrinsicsFromMsg(info), mild::InvalidInput);
}

// K all zero but K[8] = 1 (a common driver pattern) means "no calibration", as all zero does; finite
// but absurd focal lengths are refused rather than silently failing every verification.
TEST(Conversions, UncalibratedAndAbsurdIntrinsics) {
  sensor_msgs::CameraInfo info;
  info.K = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0};
  EXPECT_FALSE(intrinsicsFromMsg(info).known()) << "unknown, not an error";
  for (const double fx : {1e12, 1e-300, 0.5, 2e6}) {
    info.K = {fx, 0.0, 159.5, 0.0, 256.0, 119.5, 0.0, 0.0, 1.0};
    const std::string error = errorOf([&] { intrinsicsFromMsg(info); });
    EXPECT_NE(error.find("[1, 1e6]"), std::string::npos) << fx << ": " << error;
    info.K = {256.0, 0.0, 159.5, 0.0, fx, 119.5, 0.0, 0.0, 1.0};
    EXPECT_THROW(intrinsicsFromMsg(info), mild::InvalidInput) << "fy " << fx;
  }
  info.K = {256.0, 0.0, 1e12, 0.0, 256.0, 119.5, 0.0, 0.0, 1.0};
  EXPECT_THROW(intrinsicsFromMsg(info), mild::InvalidInput) << "cx 1e12";
  info.K = {1.0, 0.0, -5.0, 0.0, 1e6, 1e6, 0.0, 0.0, 1.0};
  EXPECT_TRUE(intrinsicsFromMsg(info).known()) << "the bounds themselves are accepted";
}

TEST(Conversions, MetricPosesAndCorrespondencesArePublishedWhenAskedFor) {
  mild::DetectionResult result;
  mild::LoopCandidate c;
  c.verification.verified = true;
  c.verification.inliers = 2;
  c.verification.inlier_matches = {{3, 7, 10}, {4, 9, 12}};
  c.verification.inlier_query_points = {{1.0f, 2.0f}, {3.0f, 4.0f}};
  c.verification.inlier_candidate_points = {{5.0f, 6.0f}, {7.0f, 8.0f}};
  c.verification.pose.valid = true;
  c.verification.pose.metric = true;
  c.verification.pose.translation = cv::Vec3d(0.5, 0.0, 1.25);
  c.verification.pose.reprojection_error = 0.75;
  result.candidates = {c};
  const LoopClosure plain = loopClosureToMsg(result, std_msgs::Header(), 10);
  EXPECT_TRUE(plain.candidates[0].inlier_query_indices.empty()) << "only with ~publish_correspondences";
  EXPECT_TRUE(plain.candidates[0].metric_translation);
  EXPECT_DOUBLE_EQ(plain.candidates[0].relative_translation.z, 1.25);
  EXPECT_DOUBLE_EQ(plain.candidates[0].reprojection_error, 0.75);
  const LoopClosure full = loopClosureToMsg(result, std_msgs::Header(), 10, true);
  const auto& m = full.candidates[0];
  EXPECT_EQ(m.inlier_query_indices, (std::vector<int32_t>{3, 4}));
  EXPECT_EQ(m.inlier_candidate_indices, (std::vector<int32_t>{7, 9}));
  EXPECT_EQ(m.inlier_query_pixels, (std::vector<float>{1, 2, 3, 4}));
  EXPECT_EQ(m.inlier_candidate_pixels, (std::vector<float>{5, 6, 7, 8}));
}

// Each input kind has its adapter, and each yields the one observation the pipeline takes.
TEST(KeyframeInputs, EachKindBecomesOneObservation) {
  const mild::CameraIntrinsics camera{300.0, 300.0, 100.0, 75.0};
  DecodedImage decoded;
  const KeyframeInputPtr raw = imageInput(image(200, 150, 1.5), camera, 2);
  EXPECT_EQ(raw->robot(), 2u);
  EXPECT_DOUBLE_EQ(raw->header().stamp.toSec(), 1.5);
  EXPECT_GE(raw->checkedBytes(InputLimits{}), 200u * 150u) << "the pixels and the header";
  const mild::Observation from_image = raw->observe(InputLimits{}, decoded);
  ASSERT_TRUE(from_image.image.has_value());
  EXPECT_EQ(from_image.image->pixels.size(), cv::Size(200, 150));
  EXPECT_EQ(decoded.image.size(), cv::Size(200, 150)) << "kept for the debug image";
  EXPECT_EQ(from_image.features.camera, camera);
  EXPECT_DOUBLE_EQ(from_image.stamp, 1.5);
  EXPECT_FALSE(from_image.id.has_value());
  EXPECT_EQ(from_image.robot, 2u);

  auto compressed = boost::make_shared<sensor_msgs::CompressedImage>();
  compressed->header.stamp = ros::Time(2.0);
  compressed->format = "png";
  cv::imencode(".png", cv::Mat(120, 160, CV_8UC1, cv::Scalar(7)), compressed->data);
  const mild::Observation from_png = compressedImageInput(compressed, {}, 1)->observe(InputLimits{}, decoded);
  ASSERT_TRUE(from_png.image.has_value());
  EXPECT_EQ(from_png.image->pixels.size(), cv::Size(160, 120));
  EXPECT_EQ(from_png.robot, 1u);

  auto keyframe = boost::make_shared<mild_lcd::Keyframe>();
  keyframe->header.stamp = ros::Time(3.0);
  keyframe->has_id = true;
  keyframe->id = 42;
  const mild::Observation from_features = keyframeInput(keyframe)->observe(InputLimits{}, decoded);
  EXPECT_FALSE(from_features.image.has_value());
  EXPECT_TRUE(decoded.image.empty()) << "no image to draw on";
  EXPECT_EQ(from_features.id, std::optional<uint64_t>(42));
  EXPECT_DOUBLE_EQ(from_features.stamp, 3.0);
  EXPECT_TRUE(from_features.features.keypoints.empty());
}

TEST(Worker, AnImagesCameraIsStoredWithItsKeyframe) {
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>()));
  KeyframeWorker::Hooks hooks;
  hooks.publish = [](const ProcessedKeyframe&) {};
  KeyframeWorker worker(shared, 10, 256u << 20, InputLimits{1000 * 1000, 10000}, hooks);
  worker.start();
  const mild::CameraIntrinsics camera{300.0, 300.0, 100.0, 75.0};
  worker.push(imageInput(image(200, 150, 1.0), camera));
  worker.push(imageInput(image(200, 150, 2.0)));
  worker.waitIdle();
  ASSERT_EQ(shared.robot(0).size(), 2u);
  EXPECT_EQ(shared.robot(0).record(0).camera, camera);
  EXPECT_FALSE(shared.robot(0).record(1).camera.known());
}

// --- the worker's two stages (~extraction_thread): keyframe k+1 decoded and extracted while k is
// queried, verified and stored.

sensor_msgs::ImagePtr imageOf(const cv::Mat& grey, double stamp) {
  auto msg = boost::make_shared<sensor_msgs::Image>();
  msg->header.stamp = ros::Time(stamp);
  msg->width = static_cast<uint32_t>(grey.cols);
  msg->height = static_cast<uint32_t>(grey.rows);
  msg->encoding = sensor_msgs::image_encodings::MONO8;
  msg->step = static_cast<uint32_t>(grey.cols);
  msg->data.assign(grey.data, grey.data + grey.total());
  return msg;
}

// Everything a keyframe's answer says, in the order the answers came.
struct Answers {
  std::mutex mutex;
  std::vector<ProcessedKeyframe> published;
  std::vector<std::string> events;  // "answered (stamp s)" or the warning of a refusal, in order
};

KeyframeWorker::Hooks recordingHooks(Answers& answers) {
  KeyframeWorker::Hooks hooks;
  hooks.publish = [&answers](const ProcessedKeyframe& k) {
    std::lock_guard<std::mutex> lock(answers.mutex);
    answers.published.push_back(k);
    answers.events.push_back("answered (stamp " + std::to_string(k.header.stamp.toSec()) + ")");
  };
  hooks.warn = [&answers](const std::string& what) {
    std::lock_guard<std::mutex> lock(answers.mutex);
    answers.events.push_back(what);
  };
  return hooks;
}

TEST(WorkerStages, TheExtractionThreadGivesTheSameAnswersAsOneThread) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  ASSERT_EQ(frames.size(), 60u);
  Answers answers[2];
  for (const bool extraction_thread : {false, true}) {
    SharedDetector shared;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(fixtureParams())));
    KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{}, recordingHooks(answers[extraction_thread]),
                          extraction_thread);
    worker.start();
    EXPECT_EQ(worker.extractionThread(), extraction_thread);
    for (size_t i = 0; i < frames.size(); ++i) worker.push(imageInput(imageOf(frames[i], 0.5 * i)));
    worker.waitIdle();
    const WorkerCounters c = worker.counters();
    EXPECT_EQ(c.processed, frames.size());
    EXPECT_EQ(c.dropped + c.rejected + c.discarded, 0u);
  }
  const std::vector<ProcessedKeyframe>& one = answers[0].published;
  const std::vector<ProcessedKeyframe>& two = answers[1].published;
  ASSERT_EQ(one.size(), frames.size());
  ASSERT_EQ(two.size(), frames.size());
  size_t candidates = 0, accepted = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    SCOPED_TRACE("keyframe " + std::to_string(i));
    const mild::DetectionResult& a = one[i].result;
    const mild::DetectionResult& b = two[i].result;
    EXPECT_EQ(two[i].header.stamp, one[i].header.stamp) << "in arrival order";
    EXPECT_EQ(b.query_id, a.query_id);
    EXPECT_EQ(b.query_id, i);
    EXPECT_EQ(two[i].database_size, one[i].database_size);
    EXPECT_EQ(b.stats.features, a.stats.features);
    EXPECT_EQ(b.similarity, a.similarity);
    EXPECT_GT(b.stats.extract_ms, 0.0) << "the extraction ahead is still reported";
    EXPECT_GT(a.stats.extract_ms, 0.0);
    EXPECT_FALSE(two[i].image.image.empty()) << "the decoded image still reaches the debug image";
    ASSERT_EQ(b.candidates.size(), a.candidates.size());
    for (size_t c = 0; c < a.candidates.size(); ++c) {
      EXPECT_EQ(b.candidates[c].id, a.candidates[c].id);
      EXPECT_EQ(b.candidates[c].robot, a.candidates[c].robot);
      EXPECT_EQ(b.candidates[c].probability, a.candidates[c].probability);
      EXPECT_EQ(b.candidates[c].filter_probability, a.candidates[c].filter_probability);
      EXPECT_EQ(b.candidates[c].similarity, a.candidates[c].similarity);
      EXPECT_EQ(b.candidates[c].accepted, a.candidates[c].accepted);
      EXPECT_EQ(b.candidates[c].verification.inliers, a.candidates[c].verification.inliers);
      accepted += a.candidates[c].accepted ? 1 : 0;
    }
    candidates += a.candidates.size();
  }
  EXPECT_GT(candidates, 0u);
  EXPECT_GT(accepted, 0u) << "the fixture's revisit is found";
}

mild_lcd::KeyframePtr keyframeMsg(double stamp, std::optional<uint64_t> id, uint32_t descriptor_bytes = 32) {
  auto kf = boost::make_shared<mild_lcd::Keyframe>();
  kf->header.stamp = ros::Time(stamp);
  kf->has_id = id.has_value();
  kf->id = id.value_or(0);
  kf->descriptor_bytes = descriptor_bytes;
  kf->keypoints.resize(3);
  for (size_t i = 0; i < 3; ++i) kf->keypoints[i].x = kf->keypoints[i].y = 10.0f * static_cast<float>(i + 1);
  kf->descriptors.assign(3 * descriptor_bytes, static_cast<uint8_t>(stamp));
  return kf;
}

// A PNG whose header passes the size checks made as it is pushed, and whose pixels do not decode.
sensor_msgs::CompressedImagePtr corruptPng(double stamp) {
  auto msg = boost::make_shared<sensor_msgs::CompressedImage>();
  msg->header.stamp = ros::Time(stamp);
  msg->format = "png";
  cv::imencode(".png", cv::Mat(40, 40, CV_8UC1, cv::Scalar(90)), msg->data);
  for (size_t i = 41; i + 12 < msg->data.size(); ++i) msg->data[i] ^= 0x5A;  // IDAT's data, not IHDR
  return msg;
}

// Refusals by either stage (an undecodable image by stage 1, a duplicate id or another width by the
// detector in stage 2) keep their place among the answers, with the messages one thread gives.
TEST(WorkerStages, AnswersAndRefusalsKeepTheirOrderAndAddUp) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  Answers answers[2];
  for (const bool extraction_thread : {false, true}) {
    SharedDetector shared;
    mild::DetectorParams p = fixtureParams();
    p.verification.enabled = false;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(p)));
    KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{1000 * 1000, 10000},
                          recordingHooks(answers[extraction_thread]), extraction_thread);
    worker.start();
    double stamp = 1.0;
    for (size_t i = 0; i < 12; ++i) {
      worker.push(imageInput(imageOf(frames[i], stamp++)));  // ids 0, 1, ...: the next free one
      switch (i % 4) {
        case 0:
          worker.push(compressedImageInput(corruptPng(stamp++)));  // refused by stage 1, decoding
          break;
        case 1:
          worker.push(keyframeInput(keyframeMsg(stamp++, 0)));  // id 0 is taken: refused by the detector
          break;
        case 2:
          worker.push(keyframeInput(keyframeMsg(stamp++, 100000 - i, 16)));  // another width: refused too
          break;
        default:
          worker.push(keyframeInput(keyframeMsg(stamp++, 100000 - i)));  // features, an id below the images': answered
          break;
      }
    }
    worker.waitIdle();
    const WorkerCounters c = worker.counters();
    EXPECT_EQ(c.processed, 15u);
    EXPECT_EQ(c.rejected, 9u);
    EXPECT_EQ(c.processed + c.rejected + c.dropped + c.discarded, 24u);
  }
  EXPECT_EQ(answers[1].events, answers[0].events) << "the same answers and messages, in the same order";
  ASSERT_EQ(answers[1].events.size(), 24u);
  for (size_t i = 0; i < answers[1].events.size(); ++i) {
    const std::string stamp = std::to_string(static_cast<double>(i + 1));
    EXPECT_NE(answers[1].events[i].find("(stamp " + stamp + ")"), std::string::npos) << answers[1].events[i];
  }
  EXPECT_NE(answers[1].events[1].find("cannot be decoded"), std::string::npos) << answers[1].events[1];
  EXPECT_NE(answers[1].events[3].find("already in the database"), std::string::npos) << answers[1].events[3];
}

// A worker whose stages are watched: how many keyframes stage 1 has made ready, and a wait for it.
struct StageWatch {
  std::mutex mutex;
  std::condition_variable changed;
  int staged = 0;

  void onStaged() {
    {
      std::lock_guard<std::mutex> lock(mutex);
      ++staged;
    }
    changed.notify_all();
  }
  bool waitFor(int n, std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, timeout, [&] { return staged >= n; });
  }
};

// Keyframe k+1 is extracted while keyframe k is in stage 2 (here: its publish waits until stage 1
// has made the next one ready), and while the detector lock is held by someone else (a service).
// One thread cannot: the same wait runs out.
TEST(WorkerStages, TheNextKeyframeIsExtractedWhileTheDetectorWorks) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  for (const bool extraction_thread : {true, false}) {
    SCOPED_TRACE(extraction_thread ? "extraction thread" : "one thread");
    SharedDetector shared;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(fixtureParams())));
    StageWatch watch;
    std::atomic<bool> first{true}, overlapped{false};
    std::atomic<double> first_extract_ms{0.0};
    std::atomic<int> extracted_ahead{0};
    KeyframeWorker::Hooks hooks;
    hooks.staged = [&](const std_msgs::Header&, bool has_features) {
      extracted_ahead += has_features ? 1 : 0;
      watch.onStaged();
    };
    hooks.publish = [&](const ProcessedKeyframe& k) {
      if (!first.exchange(false)) return;
      first_extract_ms = k.result.stats.extract_ms;
      // Keyframe 0 is stored and being answered: keyframe 1 gets extracted meanwhile, or never.
      overlapped = watch.waitFor(2, extraction_thread ? std::chrono::seconds(20) : std::chrono::milliseconds(300));
    };
    KeyframeWorker worker(shared, 10, 256u << 20, InputLimits{}, hooks, extraction_thread);
    worker.start();
    {
      const auto busy = shared.lock();  // a service holds the detector
      worker.push(imageInput(imageOf(frames[0], 1.0)));
      worker.push(imageInput(imageOf(frames[1], 2.0)));
      if (extraction_thread) {
        EXPECT_TRUE(watch.waitFor(1, std::chrono::seconds(20))) << "extracted without the detector lock";
      }
    }
    worker.waitIdle();
    EXPECT_EQ(extracted_ahead.load(), extraction_thread ? 2 : 0) << "stage 1 extracts, not only decodes";
    EXPECT_EQ(overlapped.load(), extraction_thread);
    EXPECT_GT(first_extract_ms.load(), 0.0);
    EXPECT_EQ(worker.counters().processed, 2u);
  }
}

// stop() with a keyframe in each stage and more waiting: the detector's finishes and is answered,
// the one extracted (or still being extracted) and those waiting are discarded and counted, both
// threads are joined, and the worker is idle.
TEST(WorkerStages, StoppingWithKeyframesInBothStagesCountsThem) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  for (const bool handed_over : {true, false}) {
    SCOPED_TRACE(handed_over ? "keyframe 1 handed over" : "keyframe 1 being extracted");
    SharedDetector shared;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(fixtureParams())));
    StageWatch watch;
    std::mutex publish_gate, stage_gate;
    std::unique_lock<std::mutex> hold_publish(publish_gate);  // keyframe 0 waits in its publish
    std::unique_lock<std::mutex> hold_stage(stage_gate, std::defer_lock);
    if (!handed_over) hold_stage.lock();  // keyframe 1 waits in stage 1, before the hand-off
    std::atomic<int> published{0};
    KeyframeWorker::Hooks hooks;
    hooks.staged = [&](const std_msgs::Header& h, bool) {
      watch.onStaged();
      if (h.stamp.toSec() == 1.0) std::lock_guard<std::mutex> wait(stage_gate);
    };
    hooks.publish = [&](const ProcessedKeyframe&) {
      ++published;
      std::lock_guard<std::mutex> wait(publish_gate);
    };
    KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{}, hooks, true);
    worker.start();
    for (int i = 0; i < 10; ++i) worker.push(imageInput(imageOf(frames[static_cast<size_t>(i)], i)));
    EXPECT_TRUE(watch.waitFor(2, std::chrono::seconds(20)));
    EXPECT_TRUE(eventually([&] { return published.load() > 0; }));
    if (handed_over) {
      EXPECT_TRUE(eventually([&] { return worker.counters().handed_over == 1; }));
    }
    EXPECT_EQ(worker.counters().queued, 8u) << "one keyframe in each stage";
    std::thread stopper([&] { worker.stop(); });
    EXPECT_TRUE(eventually([&] { return worker.counters().discarded >= (handed_over ? 9u : 8u); }));
    if (!handed_over) hold_stage.unlock();
    hold_publish.unlock();
    stopper.join();
    worker.waitIdle();  // returns: nothing is left in either stage
    const WorkerCounters c = worker.counters();
    EXPECT_EQ(c.processed, 1u) << "the detector's keyframe finished";
    EXPECT_EQ(c.discarded, 9u);
    EXPECT_EQ(c.processed + c.discarded + c.dropped + c.rejected, 10u);
    EXPECT_EQ(published.load(), 1);
    EXPECT_EQ(shared.robot(0).size(), 1u);
    EXPECT_EQ(worker.push(imageInput(imageOf(frames[10], 10.0))), KeyframeWorker::Pushed::kDroppedOldest)
        << "a stopped worker takes nothing";
  }
}

// discardPending (the reset service) empties the hand-off too: an extracted keyframe waiting for
// the detector is as much "waiting" as one in the queue.
TEST(WorkerStages, DiscardingPendingKeyframesEmptiesTheHandOff) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(fixtureParams())));
  StageWatch watch;
  std::mutex gate;
  std::unique_lock<std::mutex> hold(gate);
  KeyframeWorker::Hooks hooks;
  hooks.staged = [&](const std_msgs::Header&, bool) { watch.onStaged(); };
  hooks.publish = [&](const ProcessedKeyframe&) { std::lock_guard<std::mutex> wait(gate); };
  KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{}, hooks, true);
  worker.start();
  for (int i = 0; i < 5; ++i) worker.push(imageInput(imageOf(frames[static_cast<size_t>(i)], i)));
  EXPECT_TRUE(watch.waitFor(2, std::chrono::seconds(20)));
  EXPECT_TRUE(eventually([&] { return worker.counters().handed_over == 1; }));
  // Keyframe 0 in stage 2, keyframe 1 extracted, 2-4 queued (stage 1 takes none until the hand-off
  // is free).
  EXPECT_EQ(worker.counters().queued, 3u);
  EXPECT_EQ(worker.discardPending(), 4u);
  EXPECT_EQ(worker.counters().handed_over, 0u);
  hold.unlock();
  worker.waitIdle();
  const WorkerCounters c = worker.counters();
  EXPECT_EQ(c.processed, 1u);
  EXPECT_EQ(c.discarded, 4u);
  worker.push(imageInput(imageOf(frames[5], 5.0)));
  worker.waitIdle();
  EXPECT_EQ(worker.counters().processed, 2u) << "and goes on";
}

}  // namespace
}  // namespace mild_lcd
