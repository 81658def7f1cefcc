// test_ros_parts: where maps are saved and loaded (ros/database_store.hpp): start-up failures, autosave, the services'
// folder.

#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

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
      d->process(mild::Observation::ofFeatures(std::move(f), 1.0 * k));
    }
    return d;
  }
  NodeSettings settings(const std::string& extra = "") const {
    return settingsFrom("database_dir: " + dir_.string() + "\n" + extra);
  }
};

// Any failure to load at start-up (here a map over ~max_database_mb: a CapacityError, not bad
// input) leaves the file as it is and keeps save_on_shutdown from writing over it.
TEST_F(Store, AnyStartUpLoadFailureLeavesTheMapAndDisablesSaving) {
  SharedDetector original;
  original.setTeam(std::make_unique<mild::RobotTeam>(detector(120)));
  mild::saveMap(original.robot(0).map(), (dir_ / "map.db").string());
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
  mild::saveMap(detector(2)->map(), (dir_ / "small.db").string());
  const std::string merge_error = errorOf([&] { store.merge(running, "small.db"); });
  EXPECT_NE(merge_error.find("without merge replaces it"), std::string::npos) << merge_error;
  EXPECT_EQ(running.robot(0).map().size(), 0u);
  EXPECT_EQ(fs::file_size(dir_ / "map.db"), size) << "the map is untouched";
  EXPECT_EQ(mild::readMapFile((dir_ / "map.db").string()).records.size(), 120u);
}

// Issue 49 item 1: the user loads another map by hand (an empty one, a one-keyframe backup) after the
// start-up load was refused. Keyframes are taken again, but neither autosave nor save_on_shutdown
// nor a save_database without a path writes over the map that was refused; a save_database that
// names it does (the user's explicit decision), and so does loading that very file by hand.
TEST_F(Store, AMapRefusedAtStartUpStaysProtectedWhateverIsLoadedInBetween) {
  SharedDetector original;
  original.setTeam(std::make_unique<mild::RobotTeam>(detector(120)));
  mild::saveMap(original.robot(0).map(), (dir_ / "map.db").string());
  const auto size = fs::file_size(dir_ / "map.db");
  mild::saveMap(detector(0)->map(), (dir_ / "empty.db").string());
  mild::saveMap(detector(1)->map(), (dir_ / "backup.db").string());

  DatabaseStore store(
      settings("database_path: map.db\nload_on_start: true\nsave_on_shutdown: true\nmax_database_mb: 1\n"));
  SharedDetector running;
  running.setTeam(std::make_unique<mild::RobotTeam>(detector(0)));
  EXPECT_THROW(store.loadOnStart(running), mild::Error);
  const auto untouched = [&](const std::string& when) {
    EXPECT_EQ(fs::file_size(dir_ / "map.db"), size) << when;
    EXPECT_EQ(mild::readMapFile((dir_ / "map.db").string()).records.size(), 120u) << when;
  };

  for (const std::string& by_hand : {std::string("empty.db"), std::string("backup.db")}) {
    const std::string loaded = store.load(running, by_hand, false).message;
    EXPECT_NE(loaded.find("is protected"), std::string::npos) << "the reply says so: " << loaded;
    EXPECT_TRUE(running.failure[0].empty()) << "keyframes are taken again after " << by_hand;
    ++running.changes;  // as the worker does after each keyframe
    const std::string autosaved = store.autosave(running);
    untouched("autosave after loading " + by_hand);
    const std::string shutdown = store.saveOnShutdown(running);
    EXPECT_NE(shutdown.find("not saving"), std::string::npos) << shutdown;
    EXPECT_NE(shutdown.find("map.db"), std::string::npos) << "names the protected map: " << shutdown;
    untouched("save_on_shutdown after loading " + by_hand);
    const std::string refused = errorOf([&] { store.save(running, ""); });
    EXPECT_NE(refused.find("protected"), std::string::npos) << refused;
    untouched("save_database without a path after loading " + by_hand);
  }
  // Saving elsewhere is fine.
  EXPECT_NE(store.save(running, "today.db").find("saved 1 keyframes"), std::string::npos);
  untouched("a save elsewhere");
  // Naming it is the user's decision: saved, and from then on the map is this run's.
  EXPECT_NE(store.save(running, "map.db").find("saved 1 keyframes"), std::string::npos);
  EXPECT_EQ(mild::readMapFile((dir_ / "map.db").string()).records.size(), 1u);
  ++running.changes;
  EXPECT_NE(store.autosave(running).find("saved"), std::string::npos) << "autosave resumes";
  EXPECT_NE(store.saveOnShutdown(running).find("saved"), std::string::npos);
}

// A map that could not be read at start-up (here: corrupt) and is then restored by the user and
// loaded by hand from ~database_path: the running map holds it, so saves resume.
TEST_F(Store, LoadingTheRefusedMapItselfByHandLiftsItsProtection) {
  std::ofstream(dir_ / "map.db") << "not a map";
  DatabaseStore store(settings("database_path: map.db\nload_on_start: true\nsave_on_shutdown: true\n"));
  SharedDetector running;
  running.setTeam(std::make_unique<mild::RobotTeam>(detector(0)));
  EXPECT_THROW(store.loadOnStart(running), mild::Error);
  mild::saveMap(detector(4)->map(), (dir_ / "map.db").string());  // the user restores it
  EXPECT_EQ(store.load(running, "", false).keyframes, 4u);
  ++running.changes;
  EXPECT_NE(store.autosave(running).find("saved 4 keyframes"), std::string::npos);
}

// The services are up before the worker loads the map (several robots load one after another):
// until then a save without a path once replaced the saved map with the empty one, and a load by
// hand was replaced by the start-up load. Both are refused, and nothing is saved, until it is in.
TEST_F(Store, NothingIsSavedOrLoadedBeforeTheStartUpLoad) {
  mild::saveMap(detector(4)->map(), (dir_ / "map.db").string());
  mild::saveMap(detector(2)->map(), (dir_ / "other.db").string());
  DatabaseStore store(settings("database_path: map.db\nload_on_start: true\nsave_on_shutdown: true\n"));
  SharedDetector running;
  running.setTeam(std::make_unique<mild::RobotTeam>(detector(0)));
  ++running.changes;
  EXPECT_NE(errorOf([&] { store.save(running, ""); }).find("still being loaded"), std::string::npos);
  EXPECT_NE(errorOf([&] { store.load(running, "other.db", false); }).find("still being loaded"), std::string::npos);
  EXPECT_NE(errorOf([&] { store.merge(running, "other.db"); }).find("still being loaded"), std::string::npos);
  EXPECT_EQ(store.autosave(running), "");
  EXPECT_NE(store.saveOnShutdown(running).find("never loaded"), std::string::npos);
  EXPECT_EQ(mild::readMapFile((dir_ / "map.db").string()).records.size(), 4u) << "the saved map is whole";
  store.loadOnStart(running);
  EXPECT_EQ(running.robot(0).map().size(), 4u);
  EXPECT_NE(store.save(running, "").find("saved 4 keyframes"), std::string::npos);
}

TEST_F(Store, AMissingMapStartsEmptyAndIsSavedOnShutdown) {
  DatabaseStore store(settings("database_path: new.db\nload_on_start: true\nsave_on_shutdown: true\n"));
  SharedDetector running;
  running.setTeam(std::make_unique<mild::RobotTeam>(detector(3)));
  EXPECT_NE(store.loadOnStart(running).find("does not exist yet"), std::string::npos);
  EXPECT_NE(store.saveOnShutdown(running).find("saved 3 keyframes"), std::string::npos);
  EXPECT_EQ(mild::readMapFile((dir_ / "new.db").string()).records.size(), 3u);
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
  EXPECT_EQ(mild::readMapFile((dir_ / "auto.db").string()).records.size(), 3u);
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
  EXPECT_EQ(other.robot(0).map().size(), 4u);
  EXPECT_THROW(DatabaseStore(settings("database_path: /etc/passwd\n")), mild::InvalidInput)
      << "~database_path outside ~database_dir stops the node at start-up";
}

}  // namespace
}  // namespace mild_lcd
