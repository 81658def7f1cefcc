#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>

#include <zlib.h>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include <cstring>

#include "../common/scratch_folder.hpp"
#include "fixture_params.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/detector/process_image.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "test_images.hpp"

namespace fs = std::filesystem;

namespace mild {
namespace {

const std::string& kFixture = test::kFixtureDir;

using test::fixtureFrames;
using test::fixtureParams;

void process(LoopDetector& d, size_t first, size_t last, std::vector<DetectionResult>* out = nullptr) {
  for (size_t i = first; i < last; ++i) {
    DetectionResult r = processImage(d, fixtureFrames()[i], PixelFormat::kGray, 0.5 * i);
    if (out) out->push_back(std::move(r));
  }
}

void expectSameResults(const DetectionResult& a, const DetectionResult& b) {
  EXPECT_EQ(a.query_id, b.query_id);
  EXPECT_EQ(a.similarity, b.similarity) << "keyframe " << a.query_id;
  ASSERT_EQ(a.candidates.size(), b.candidates.size()) << "keyframe " << a.query_id;
  for (size_t c = 0; c < a.candidates.size(); ++c) {
    EXPECT_EQ(a.candidates[c].id, b.candidates[c].id);
    EXPECT_EQ(a.candidates[c].probability, b.candidates[c].probability);
    EXPECT_EQ(a.candidates[c].verification.inliers, b.candidates[c].verification.inliers);
  }
}

class DatabaseFile : public mild::test::ScratchFolderTest {
 protected:
  std::vector<uint8_t> bytes(const std::string& file) const {
    std::ifstream in(file, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }
  void write(const std::string& file, const std::vector<uint8_t>& data) const {
    std::ofstream(file, std::ios::binary).write(reinterpret_cast<const char*>(data.data()), data.size());
  }
};

TEST_F(DatabaseFile, ContinuingASavedSessionGivesTheUninterruptedResults) {
  const std::vector<std::pair<const char*, int>> filters = {
      {"exclusive_hypotheses", 0}, {"independent_binary", 0}, {"exclusive_hypotheses", 3}};  // 3: hub-corrected
  for (const auto& [type, hubness_min_queries] : filters) {
    SCOPED_TRACE(std::string(type) + " hubness_min_queries " + std::to_string(hubness_min_queries));
    DetectorParams params = fixtureParams();
    params.filter.type = type;
    params.filter.hubness_min_queries = hubness_min_queries;
    params.scoring.filter_type = type;  // not a fitted scorer: the test compares runs, not probabilities
    LoopDetector whole(params);
    std::vector<DetectionResult> expected;
    process(whole, 0, 60, &expected);

    LoopDetector first(params);
    process(first, 0, 35);
    saveMap(first.map(), path("map.mild"));
    LoopDetector resumed(params);
    const LoadReport report = loadMap(resumed.map(), path("map.mild"), /*continue_session=*/true);
    EXPECT_EQ(report.keyframes, 35u);
    EXPECT_EQ(resumed.map().size(), 35u);
    EXPECT_EQ(resumed.map().nextId(), 35u);
    EXPECT_EQ(resumed.map().database().index().entryCount(), first.map().database().index().entryCount());
    EXPECT_EQ(resumed.map().filter().saveState(), first.map().filter().saveState()) << "the filter state, bit for bit";
    std::vector<DetectionResult> got;
    process(resumed, 35, 60, &got);
    ASSERT_EQ(got.size(), 25u);
    size_t loops = 0;
    for (size_t i = 0; i < got.size(); ++i) {
      expectSameResults(got[i], expected[35 + i]);
      loops += got[i].candidates.empty() ? 0 : 1;
    }
    EXPECT_GT(loops, 0u);
  }
}

TEST_F(DatabaseFile, AHubCorrectedRunIsResumedOnlyWithTheCorrection) {
  DetectorParams corrected = fixtureParams();
  corrected.filter.hubness_min_queries = 3;
  LoopDetector first(corrected);
  process(first, 0, 20);
  saveMap(first.map(), path("map.mild"));
  LoopDetector plain(fixtureParams());
  process(plain, 0, 2);
  try {
    loadMap(plain.map(), path("map.mild"), /*continue_session=*/true);
    ADD_FAILURE() << "a hub-corrected filter state loaded into a plain filter";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("exclusive_hypotheses+hubness"), std::string::npos) << e.what();
  }
  EXPECT_EQ(plain.map().size(), 2u) << "the running map is left as it was";
  // A new session needs no filter state: the stored keyframes load into any filter.
  EXPECT_EQ(loadMap(plain.map(), path("map.mild"), /*continue_session=*/false).keyframes, 20u);
}

TEST_F(DatabaseFile, ANewSessionOnAStoredMapMatchesItsNewestKeyframesAtOnce) {
  LoopDetector yesterday(fixtureParams());
  process(yesterday, 0, 30);
  saveMap(yesterday.map(), path("map.mild"));

  // Today the robot starts where yesterday's run ended: keyframe 29's place.
  LoopDetector today(fixtureParams());
  loadMap(today.map(), path("map.mild"), /*continue_session=*/false);
  EXPECT_EQ(today.map().sessionStart(), 30u);
  const DetectionResult r = processImage(today, fixtureFrames()[29], PixelFormat::kGray, 100.0);
  EXPECT_EQ(r.query_id, 30u) << "ids continue after the stored ones";
  ASSERT_EQ(r.stats.eligible_keyframes, 30u) << "stored keyframes are not a moment ago";
  ASSERT_FALSE(r.similarity.empty());
  const auto best = std::max_element(r.similarity.begin(), r.similarity.end()) - r.similarity.begin();
  EXPECT_NEAR(static_cast<double>(best), 29.0, 1.0);

  // Continuing the session instead keeps yesterday's last 8 keyframes out, as an uninterrupted run would.
  DetectorParams fixed = fixtureParams();
  fixed.candidates.near_past = false;  // the fixed exclusion alone (23 keyframes are too few for a background)
  LoopDetector resumed(fixed);
  loadMap(resumed.map(), path("map.mild"), /*continue_session=*/true);
  EXPECT_EQ(processImage(resumed, fixtureFrames()[29], PixelFormat::kGray, 100.0).stats.eligible_keyframes, 23u);
}

TEST_F(DatabaseFile, BadFilesAreClearErrorsAndLeaveTheDetectorAsItWas) {
  LoopDetector source(fixtureParams());
  process(source, 0, 12);
  saveMap(source.map(), path("good.mild"));
  const std::vector<uint8_t> good = bytes(path("good.mild"));
  ASSERT_GT(good.size(), 1000u);

  LoopDetector running(fixtureParams());
  process(running, 20, 30);
  const size_t size_before = running.map().size();
  const uint64_t next_before = running.map().nextId();

  auto expectRejected = [&](const std::vector<uint8_t>& data, const std::string& words) {
    write(path("bad.mild"), data);
    try {
      loadMap(running.map(), path("bad.mild"), true);
      ADD_FAILURE() << "accepted a bad file (" << words << ")";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(path("bad.mild")), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
    EXPECT_EQ(running.map().size(), size_before);
    EXPECT_EQ(running.map().nextId(), next_before);
  };
  expectRejected({}, "empty");
  expectRejected(std::vector<uint8_t>(good.begin(), good.begin() + 20), "not a mild_lcd database");
  for (size_t cut : {size_t{32}, size_t{100}, good.size() / 2, good.size() - 1}) {
    expectRejected(std::vector<uint8_t>(good.begin(), good.begin() + static_cast<long>(cut)), "truncated");
  }
  std::vector<uint8_t> flipped = good;
  flipped[good.size() / 3] ^= 0x10;
  expectRejected(flipped, "checksum");
  std::vector<uint8_t> magic = good;
  magic[0] = 'X';
  expectRejected(magic, "not a mild_lcd database");
  std::vector<uint8_t> header = good;
  header[9] ^= 1;  // the version, without fixing the header checksum
  expectRejected(header, "corrupt header");
  expectRejected(std::vector<uint8_t>(5000, 0xAB), "not a mild_lcd database");
  EXPECT_THROW(loadMap(running.map(), path("missing.mild"), true), IoError);

  // The running detector still works and still owns its keyframes.
  EXPECT_EQ(processImage(running, fixtureFrames()[31], PixelFormat::kGray, 15.5).query_id, next_before);
}

// Makes a file's two checksums (payload, then header) match what it now holds, so that what is
// tested is read past them.
void matchChecksums(std::vector<uint8_t>& file) {
  const uint32_t payload_crc =
      static_cast<uint32_t>(crc32(crc32(0, nullptr, 0), file.data() + 32, static_cast<uInt>(file.size() - 32)));
  std::memcpy(file.data() + 24, &payload_crc, 4);
  const uint32_t header_crc = static_cast<uint32_t>(crc32(crc32(0, nullptr, 0), file.data(), 28));
  std::memcpy(file.data() + 28, &header_crc, 4);
}

TEST_F(DatabaseFile, ANewerFormatVersionIsNamed) {
  LoopDetector source(fixtureParams());
  process(source, 0, 3);
  saveMap(source.map(), path("map.mild"));
  std::vector<uint8_t> data = bytes(path("map.mild"));
  const uint32_t newer = kDatabaseFormatVersion + 1;
  std::memcpy(data.data() + 8, &newer, 4);
  matchChecksums(data);
  write(path("newer.mild"), data);
  try {
    readMapFile(path("newer.mild"));
    FAIL() << "read a version-" << newer << " file";
  } catch (const InvalidInput& e) {
    EXPECT_NE(
        std::string(e.what()).find("format version " + std::to_string(newer) + "; this mild_lcd reads versions 1 to " +
                                   std::to_string(kDatabaseFormatVersion)),
        std::string::npos)
        << e.what();
  }
}

// Version 3 keeps each keyframe's camera intrinsics, so a loaded map still gives loops a pose.
TEST_F(DatabaseFile, EachKeyframesCameraIsKept) {
  LoopDetector source(fixtureParams());
  const CameraIntrinsics camera{256.0, 255.0, 159.5, 119.5};
  processImage(source, fixtureFrames()[0], PixelFormat::kGray, 0.0, std::nullopt, camera);
  processImage(source, fixtureFrames()[1], PixelFormat::kGray, 0.5);  // one without
  saveMap(source.map(), path("map.mild"));
  const MapState state = readMapFile(path("map.mild"));
  ASSERT_EQ(state.records.size(), 2u);
  EXPECT_EQ(state.records[0].camera, camera);
  EXPECT_FALSE(state.records[1].camera.known());
}

// A file of an earlier format version made from a current one: each keyframe record loses what later
// versions added after its id, stamp and session (version 4 its place, version 3 its detection scale
// as well, version 2 its camera intrinsics as well), and the header and checksums are made to match.
// ORB's 32-byte descriptors.
std::vector<uint8_t> earlierVersion(const std::vector<uint8_t>& current, uint32_t version) {
  std::vector<uint8_t> payload(current.begin() + 32, current.end());
  const size_t removed = version == 4 ? 8 : version == 3 ? 4 + 8 : 32 + 4 + 8;
  const size_t kept = version == 4 ? 32 + 4 : version == 3 ? 32 : 0;  // what comes before, kept
  size_t at = 0;
  const auto u32 = [&](size_t pos) {
    uint32_t v;
    std::memcpy(&v, payload.data() + pos, 4);
    return v;
  };
  at += 4 + u32(0);  // parameters
  at += 4 + 8 + 4;   // descriptor width, next id, session start
  const uint32_t keyframes = u32(at);
  at += 4;
  for (uint32_t k = 0; k < keyframes; ++k) {
    at += 8 + 8 + 4 + kept;  // id, stamp, session (and the camera, kept)
    payload.erase(payload.begin() + static_cast<long>(at), payload.begin() + static_cast<long>(at + removed));
    at += 4 + u32(at) * (24 + 32);  // keypoints and descriptors
  }
  std::vector<uint8_t> earlier(32 + payload.size());
  std::copy(current.begin(), current.begin() + 32, earlier.begin());
  std::copy(payload.begin(), payload.end(), earlier.begin() + 32);
  std::memcpy(earlier.data() + 8, &version, 4);
  const uint64_t size = payload.size();
  std::memcpy(earlier.data() + 16, &size, 8);
  matchChecksums(earlier);
  return earlier;
}

// Each keyframe's place (KeyframeRecord::same_place_as) is saved and loaded; a version-4 file,
// written before keyframes had one, loads as keyframes without it.
TEST_F(DatabaseFile, EachKeyframesPlaceIsKeptAndAVersionFourFileHasNone) {
  LoopDetector source(fixtureParams());
  process(source, 0, 4);
  source.map().markSamePlace(3, source.map().record(1).id);
  saveMap(source.map(), path("map.mild"));
  const MapState state = readMapFile(path("map.mild"));
  ASSERT_EQ(state.records.size(), 4u);
  EXPECT_FALSE(state.records[0].same_place_as.has_value());
  EXPECT_EQ(state.records[3].same_place_as, source.map().record(1).id);
  write(path("v4.mild"), earlierVersion(bytes(path("map.mild")), 4));
  LoopDetector loaded(fixtureParams());
  loadMap(loaded.map(), path("v4.mild"), true);
  ASSERT_EQ(loaded.map().size(), 4u);
  for (KeyframeIndex k = 0; k < 4; ++k) EXPECT_FALSE(loaded.map().record(k).same_place_as.has_value());
  EXPECT_EQ(loaded.map().record(3).detection_scale, source.map().record(3).detection_scale);
}

// A version-2 file (written before keyframes had cameras) loads as keyframes without intrinsics.
TEST_F(DatabaseFile, VersionTwoFilesStillLoad) {
  LoopDetector source(fixtureParams());
  process(source, 0, 4);
  saveMap(source.map(), path("map.mild"));
  write(path("v2.mild"), earlierVersion(bytes(path("map.mild")), 2));

  LoopDetector loaded(fixtureParams());
  loadMap(loaded.map(), path("v2.mild"), true);
  ASSERT_EQ(loaded.map().size(), 4u);
  for (KeyframeIndex k = 0; k < 4; ++k) {
    EXPECT_EQ(loaded.map().record(k).id, source.map().record(k).id);
    EXPECT_EQ(loaded.map().record(k).keypoints.size(), source.map().record(k).keypoints.size());
    EXPECT_FALSE(loaded.map().record(k).camera.known());
  }
  EXPECT_EQ(processImage(loaded, fixtureFrames()[10], PixelFormat::kGray, 5.0).similarity,
            processImage(source, fixtureFrames()[10], PixelFormat::kGray, 5.0).similarity);
}

// The fixture's 320 x 240 frames under a cap of a quarter of their pixels: found at half size.
DetectorParams cappedParams() {
  DetectorParams p = fixtureParams();
  p.features.max_pixels = 320.0 * 240.0 / 4.0;
  return p;
}

// Version 4 keeps how much each keyframe's frame was shrunk before its keypoints were found, so a
// loaded map verifies against its keyframes at the tolerance their keypoints need, as before the
// restart: the same inliers and probabilities.
TEST_F(DatabaseFile, EachKeyframesDetectionScaleIsKept) {
  LoopDetector source(cappedParams());
  process(source, 0, 30);
  ASSERT_FLOAT_EQ(source.map().features(0).detection_scale, 2.0f);
  saveMap(source.map(), path("map.mild"));
  const MapState state = readMapFile(path("map.mild"));
  ASSERT_EQ(state.records.size(), 30u);
  for (const KeyframeRecord& r : state.records) EXPECT_FLOAT_EQ(r.detection_scale, 2.0f) << "keyframe " << r.id;

  LoopDetector loaded(cappedParams());
  loadMap(loaded.map(), path("map.mild"), true);
  EXPECT_FLOAT_EQ(loaded.map().features(0).detection_scale, 2.0f);
  for (size_t i = 52; i < 58; ++i) {  // the revisit
    expectSameResults(processImage(loaded, fixtureFrames()[i], PixelFormat::kGray, 0.5 * i),
                      processImage(source, fixtureFrames()[i], PixelFormat::kGray, 0.5 * i));
  }
}

// A version-3 file (before the detection scale was saved) loads as keyframes found at full size.
TEST_F(DatabaseFile, VersionThreeFilesLoadAsFoundAtFullSize) {
  LoopDetector source(cappedParams());
  process(source, 0, 4);
  saveMap(source.map(), path("map.mild"));
  write(path("v3.mild"), earlierVersion(bytes(path("map.mild")), 3));
  LoopDetector loaded(cappedParams());
  loadMap(loaded.map(), path("v3.mild"), true);
  ASSERT_EQ(loaded.map().size(), 4u);
  for (KeyframeIndex k = 0; k < 4; ++k) {
    EXPECT_EQ(loaded.map().record(k).camera, source.map().record(k).camera);
    EXPECT_EQ(loaded.map().record(k).keypoints.size(), source.map().record(k).keypoints.size());
    EXPECT_FLOAT_EQ(loaded.map().features(k).detection_scale, 1.0f);
  }
}

// A detection scale that cannot be one (not a number, a shrink below 1, beyond 64) is a corrupt
// file, named, even with checksums that match it; the map it was meant for is left as it was.
TEST_F(DatabaseFile, AnImpossibleDetectionScaleIsRefused) {
  LoopDetector source(cappedParams());
  process(source, 0, 2);
  saveMap(source.map(), path("map.mild"));
  const std::vector<uint8_t> good = bytes(path("map.mild"));
  uint32_t parameters;
  std::memcpy(&parameters, good.data() + 32, 4);
  const size_t scale_at = 32 + 4 + parameters + 4 + 8 + 4 + 4 + 8 + 8 + 4 + 32;  // the first keyframe's
  float stored;
  std::memcpy(&stored, good.data() + scale_at, 4);
  ASSERT_FLOAT_EQ(stored, 2.0f) << "the layout this test writes into";
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), 0.5f, 65.0f, -2.0f}) {
    std::vector<uint8_t> data = good;
    std::memcpy(data.data() + scale_at, &bad, 4);
    matchChecksums(data);
    write(path("bad.mild"), data);
    LoopDetector running(cappedParams());
    process(running, 0, 3);
    try {
      loadMap(running.map(), path("bad.mild"), true);
      FAIL() << "loaded a detection scale of " << bad;
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("detection scale"), std::string::npos) << e.what();
    }
    EXPECT_EQ(running.map().size(), 3u) << "the running map is left as it was";
  }
}

TEST_F(DatabaseFile, OtherIndexParametersRebuildTheIndexAndSaySo) {
  LoopDetector source(fixtureParams());
  process(source, 0, 20);
  saveMap(source.map(), path("map.mild"));
  DetectorParams other = fixtureParams();
  other.database.index.num_tables = 22;
  LoopDetector loaded(other);
  const LoadReport report = loadMap(loaded.map(), path("map.mild"), true);
  EXPECT_NE(report.message.find("index/num_tables 0 -> 22"), std::string::npos) << report.message;
  // The same as building the 22-table detector from the same features.
  LoopDetector fresh(other);
  process(fresh, 0, 20);
  EXPECT_EQ(loaded.map().database().index().entryCount(), fresh.map().database().index().entryCount());
  EXPECT_EQ(processImage(loaded, fixtureFrames()[50], PixelFormat::kGray, 25.0).similarity,
            processImage(fresh, fixtureFrames()[50], PixelFormat::kGray, 25.0).similarity);
}

TEST_F(DatabaseFile, SavingIntoAMissingFolderFailsAndKeepsNothingHalfWritten) {
  LoopDetector source(fixtureParams());
  process(source, 0, 3);
  EXPECT_THROW(saveMap(source.map(), path("no/such/folder/map.mild")), IoError);
  saveMap(source.map(), path("map.mild"));
  size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir_)) files += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(files, 1u) << "no temporary file left behind";
}

// A process killed (SIGKILL) at any moment of a save leaves the previous file complete and
// loadable, or the new one: never a mix, never a torn file.
TEST_F(DatabaseFile, KillingASaveAtAnyMomentLeavesALoadableFile) {
  cv::setNumThreads(0);  // no OpenCV worker threads across fork(): the child must be able to run
  LoopDetector small(fixtureParams()), large(fixtureParams());
  process(small, 0, 5);
  process(large, 0, 60);
  const std::string target = path("map.mild");
  saveMap(small.map(), target);

  // Kill moments spread over a few save cycles, however fast this build saves (sanitizers slow it).
  const auto start = std::chrono::steady_clock::now();
  saveMap(large.map(), path("timing.mild"));
  saveMap(small.map(), path("timing.mild"));
  fs::remove(path("timing.mild"));
  const int cycle_us = static_cast<int>(
      std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now() - start).count());
  std::mt19937 rng(11);
  size_t saw_small = 0, saw_large = 0;
  for (int attempt = 0; attempt < 25; ++attempt) {
    // The child reports each finished save on a pipe; the kill comes at a random moment after the
    // first large save, so both states can be the last complete one however slow fsync is today.
    int done[2];
    ASSERT_EQ(pipe(done), 0);
    const pid_t child = fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      close(done[0]);
      const char tick = 1;
      for (;;) {
        saveMap(large.map(), target);
        if (::write(done[1], &tick, 1) != 1) _exit(1);
        saveMap(small.map(), target);
      }
    }
    close(done[1]);
    char tick = 0;
    ASSERT_EQ(::read(done[0], &tick, 1), 1) << "the child's first save did not finish";
    usleep(std::uniform_int_distribution<int>(0, 2 * cycle_us + 1000)(rng));
    kill(child, SIGKILL);
    waitpid(child, nullptr, 0);
    close(done[0]);
    const MapState state = readMapFile(target);  // throws if torn
    ASSERT_TRUE(state.records.size() == 5 || state.records.size() == 60) << state.records.size();
    (state.records.size() == 5 ? saw_small : saw_large)++;
    LoopDetector check(fixtureParams());
    EXPECT_NO_THROW(loadMap(check.map(), target, true));
  }
  for (const auto& e : fs::directory_iterator(dir_)) {
    if (mild::isTemporaryFileName(e.path().filename().string())) fs::remove(e.path());  // a killed writer's leftovers
  }
  EXPECT_GT(saw_small, 0u);
  EXPECT_GT(saw_large, 0u);
}

}  // namespace
}  // namespace mild
