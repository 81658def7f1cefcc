// rostest cases for the database file through ROS: save_database / load_database services, and
// the ~database_path, ~load_on_start, ~save_on_shutdown parameters of a node started and stopped
// here. Part of test_nodelet (main() is there); selected by test/ros/nodelet_persistence.test.

#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <set>

#include <cv_bridge/cv_bridge.h>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <std_srvs/Trigger.h>
#include <opencv2/imgcodecs.hpp>

#include "../common/run_command.hpp"
#include "mild_lcd/Keyframe.h"
#include "mild_lcd/LoadDatabase.h"
#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/SaveDatabase.h"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/filter/keyframe_hubness.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "ros_test_support.hpp"

namespace fs = std::filesystem;

namespace mild_lcd::test {
namespace {

const std::string kFixtureDir = std::string(MILD_SOURCE_DIR) + "/test/data/corridor_stride5";

// The nodelet's ~database_dir (nodelet_persistence.test sets the same folder).
fs::path scratch() {
  static const fs::path dir = [] {
    const char* home = std::getenv("ROS_HOME");
    const fs::path d = fs::path(home && *home ? home : "/tmp") / "mild_persistence_test";
    fs::create_directories(d);
    return d;
  }();
  return dir;
}

std::vector<std::string> frames() {
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(kFixtureDir + "/images")) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

// Publishes fixture frames [first, last) as images and waits for their answers.
std::vector<mild_lcd::LoopClosure> feed(size_t first, size_t last) {
  ros::NodeHandle nh;
  ros::Publisher images = nh.advertise<sensor_msgs::Image>("/camera/image", 100);
  TopicLog<mild_lcd::LoopClosure> outputs("loop_closure");
  EXPECT_TRUE(outputs.waitForPublisher(20.0));
  EXPECT_TRUE(waitForSubscriber(images, 20.0));
  const auto files = frames();
  for (size_t i = first; i < last; ++i) {
    std_msgs::Header header;
    header.stamp = ros::Time(1000.0 + 0.5 * i);
    images.publish(
        cv_bridge::CvImage(header, sensor_msgs::image_encodings::MONO8, cv::imread(files[i], cv::IMREAD_GRAYSCALE))
            .toImageMsg());
    ros::WallDuration(0.05).sleep();  // well within the queue; keeps the test's own send queue short
  }
  EXPECT_TRUE(outputs.waitForCount(last - first, 60.0));
  return outputs.messages();
}

template <class Srv>
Srv call(const std::string& name, const typename Srv::Request& request) {
  Srv srv;
  srv.request = request;
  EXPECT_TRUE(ros::service::waitForService(name, ros::Duration(10.0)));
  EXPECT_TRUE(ros::service::call(name, srv));
  return srv;
}

TEST(Persistence, SaveResetLoadAndDetectLoopsAgainstTheLoadedMap) {
  const std::string map = (scratch() / "corridor.mild").string();
  ASSERT_EQ(feed(0, 47).size(), 47u);  // the first lap

  mild_lcd::SaveDatabase::Request save;
  save.path = map;
  const auto saved = call<mild_lcd::SaveDatabase>("save_database", save);
  ASSERT_TRUE(saved.response.success) << saved.response.message;
  EXPECT_EQ(mild::readMapFile(map).records.size(), 47u);

  std_srvs::Trigger reset;
  ASSERT_TRUE(ros::service::call("reset", reset));

  mild_lcd::LoadDatabase::Request load;
  load.path = map;  // a new session on the stored map
  const auto loaded = call<mild_lcd::LoadDatabase>("load_database", load);
  ASSERT_TRUE(loaded.response.success) << loaded.response.message;
  EXPECT_EQ(loaded.response.keyframes, 47u);

  // The revisit, in a new session: ids continue and the loop to the stored lap is found.
  const mild::GroundTruth truth = mild::loadGroundTruth(kFixtureDir + "/gt_loops.txt");
  const auto revisit = feed(47, 60);
  ASSERT_EQ(revisit.size(), 13u);
  std::set<uint64_t> detected;
  for (size_t i = 0; i < revisit.size(); ++i) {
    EXPECT_EQ(revisit[i].query_id, 47 + i);
    for (const auto& c : revisit[i].candidates) {
      if (!c.accepted) continue;  // what a back-end acts on
      const std::pair<int, int> pair(static_cast<int>(revisit[i].query_id), static_cast<int>(c.id));
      EXPECT_TRUE(truth.right.count(pair) || truth.dont_care.count(pair)) << pair.first << " -> " << pair.second;
      if (truth.right.count(pair) && c.verified) detected.insert(revisit[i].query_id);
    }
  }
  EXPECT_GE(detected.size(), 3u);

  // A corrupt file is refused and the database stays as it is.
  const std::string corrupt = (scratch() / "corrupt.mild").string();
  fs::copy_file(map, corrupt, fs::copy_options::overwrite_existing);
  fs::resize_file(corrupt, fs::file_size(corrupt) / 2);
  load.path = corrupt;
  const auto refused = call<mild_lcd::LoadDatabase>("load_database", load);
  EXPECT_FALSE(refused.response.success);
  EXPECT_NE(refused.response.message.find("truncated"), std::string::npos) << refused.response.message;
  EXPECT_EQ(refused.response.keyframes, 60u);
  // Only inside ~database_dir, never through a link, never over something that is not a file.
  std::ofstream(scratch().parent_path() / "victim.txt") << "precious";
  fs::remove(scratch() / "link.mild");
  fs::create_symlink(scratch().parent_path() / "victim.txt", scratch() / "link.mild");
  for (const std::string& bad : {std::string("../victim.txt"), (scratch().parent_path() / "victim.txt").string(),
                                 std::string("link.mild"), std::string("/dev/null")}) {
    save.path = bad;
    const auto refused_save = call<mild_lcd::SaveDatabase>("save_database", save);
    EXPECT_FALSE(refused_save.response.success) << bad;
    EXPECT_FALSE(refused_save.response.message.empty()) << bad;
  }
  std::ifstream victim(scratch().parent_path() / "victim.txt");
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(victim)), std::istreambuf_iterator<char>()), "precious");
  save.path = "sites/corridor.mild";  // a sub-folder inside is made
  EXPECT_TRUE(call<mild_lcd::SaveDatabase>("save_database", save).response.success);
  EXPECT_TRUE(fs::exists(scratch() / "sites" / "corridor.mild"));

  // Loading a FIFO or a folder answers at once, success false; the database is unchanged.
  fs::remove(scratch() / "fifo.mild");
  ASSERT_EQ(mkfifo((scratch() / "fifo.mild").c_str(), 0600), 0);
  fs::create_directories(scratch() / "folder.mild");
  for (const std::string& bad : {std::string("fifo.mild"), std::string("folder.mild")}) {
    load.path = bad;
    const auto answer = call<mild_lcd::LoadDatabase>("load_database", load);
    EXPECT_FALSE(answer.response.success) << bad;
    EXPECT_NE(answer.response.message.find("regular files"), std::string::npos) << answer.response.message;
    EXPECT_EQ(answer.response.keyframes, 60u);
  }
}

// load_database with merge: another robot's map (the first lap, under ids of its own) joins the
// running map, and the running session's revisit closes loops into it.
TEST(Persistence, MergeAddsASavedMapToTheRunningOne) {
  std_srvs::Trigger reset;
  ASSERT_TRUE(ros::service::call("reset", reset));
  ASSERT_EQ(feed(0, 47).size(), 47u);
  mild_lcd::SaveDatabase::Request save;
  save.path = "lap.mild";
  ASSERT_TRUE(call<mild_lcd::SaveDatabase>("save_database", save).response.success);
  // The same lap as another robot would have saved it: ids 1000.., its own session numbering.
  mild::MapState state = mild::readMapFile((scratch() / "lap.mild").string());
  for (auto& r : state.records) r.id += 1000;
  state.next_id += 1000;
  mild::LoopDetector other;
  other.map().restore(std::move(state), false);
  mild::saveMap(other.map(), (scratch() / "other_robot.mild").string());

  ASSERT_TRUE(ros::service::call("reset", reset));
  ASSERT_EQ(feed(0, 20).size(), 20u);  // ids 0..19: the running session
  mild_lcd::LoadDatabase::Request load;
  load.path = "lap.mild";  // ids 0..46 again
  load.merge = true;
  const auto clash = call<mild_lcd::LoadDatabase>("load_database", load);
  EXPECT_FALSE(clash.response.success);
  EXPECT_NE(clash.response.message.find("is in both maps"), std::string::npos) << clash.response.message;
  EXPECT_EQ(clash.response.keyframes, 20u);
  load.continue_session = true;
  load.path = "other_robot.mild";
  EXPECT_FALSE(call<mild_lcd::LoadDatabase>("load_database", load).response.success) << "merge excludes continue";
  load.continue_session = false;
  const auto merged = call<mild_lcd::LoadDatabase>("load_database", load);
  ASSERT_TRUE(merged.response.success) << merged.response.message;
  EXPECT_EQ(merged.response.keyframes, 67u);

  const mild::GroundTruth truth = mild::loadGroundTruth(kFixtureDir + "/gt_loops.txt");
  const auto revisit = feed(47, 60);
  ASSERT_EQ(revisit.size(), 13u);
  std::set<uint64_t> across;
  for (size_t i = 0; i < revisit.size(); ++i) {
    EXPECT_EQ(revisit[i].query_id, 1047 + i) << "ids continue above both maps";
    for (const auto& c : revisit[i].candidates) {
      if (!c.accepted) continue;
      const bool merged_map = c.id >= 1000;
      EXPECT_EQ(c.session != revisit[i].query_session, merged_map) << c.id;
      const std::pair<int, int> pair(static_cast<int>(47 + i), static_cast<int>(merged_map ? c.id - 1000 : c.id));
      // The other robot's keyframes are exempt from the temporal exclusion: its view of the very
      // place the query sees (frame 46 for query 47) is a right answer the ground truth leaves out.
      const bool same_place = merged_map && pair.first - pair.second < 8;
      EXPECT_TRUE(truth.right.count(pair) || truth.dont_care.count(pair) || same_place)
          << pair.first << " -> " << pair.second;
      if (merged_map && truth.right.count(pair)) across.insert(revisit[i].query_id);
    }
  }
  EXPECT_GE(across.size(), 3u) << "loops into the merged map";
}

// A node of our own in /session: started with ~load_on_start on the map saved above, fed one
// keyframe, stopped with SIGINT: ~save_on_shutdown writes the grown map.
pid_t startNode(const std::string& ns, const std::string& map) {
  const pid_t pid = fork();
  if (pid == 0) {
    const std::string ns_arg = "__ns:=" + ns, path_arg = "_database_path:=" + map;
    execl(MILD_NODE_BIN, MILD_NODE_BIN, ns_arg.c_str(), "__name:=mild_lcd", path_arg.c_str(), "_load_on_start:=true",
          "_save_on_shutdown:=true", "_use_image_input:=false", static_cast<char*>(nullptr));
    _exit(127);
  }
  return pid;
}

TEST(Persistence, LoadOnStartAndSaveOnShutdown) {
  const std::string map = (scratch() / "corridor.mild").string();
  ASSERT_TRUE(fs::exists(map)) << "written by the previous case";
  const size_t stored = mild::readMapFile(map).records.size();

  const pid_t node = startNode("/session", map);
  ASSERT_GT(node, 0);
  {
    ros::NodeHandle nh;
    ros::Publisher keyframes = nh.advertise<mild_lcd::Keyframe>("/session/keyframe", 10);
    TopicLog<mild_lcd::LoopClosure> outputs("/session/loop_closure");
    ASSERT_TRUE(outputs.waitForPublisher(30.0));
    ASSERT_TRUE(waitForSubscriber(keyframes, 30.0));
    mild_lcd::Keyframe kf;
    kf.header.stamp = ros::Time(2000.0);
    kf.keypoints.resize(1);
    kf.descriptors.assign(32, 0x3C);
    keyframes.publish(kf);
    ASSERT_TRUE(outputs.waitForCount(1, 20.0));
    EXPECT_EQ(outputs.messages()[0].query_id, stored) << "ids continue after the loaded map";
    EXPECT_EQ(outputs.messages()[0].database_size, static_cast<int>(stored + 1));
  }
  kill(node, SIGINT);
  int status = 0;
  waitpid(node, &status, 0);
  EXPECT_EQ(mild::readMapFile(map).records.size(), stored + 1) << "saved on shutdown";

  fs::remove_all(scratch());
}

// A mild_lcd with keyframe input in `ns`, saving to `map`: a nodelet manager of our own and a loader
// that loads the nodelet into it (rosrun execs the manager itself: the pid is the manager's), or the
// standalone node.
struct RunningNode {
  pid_t process = -1, loader = -1;  // the manager or the node; the loader (none for the node)

  RunningNode(const std::string& ns, const std::string& map, int autosave_period, bool in_manager) {
    const std::string ns_arg = "__ns:=" + ns, path_arg = "_database_path:=" + map,
                      period_arg = "_autosave_period:=" + std::to_string(autosave_period),
                      manager_name = ns + "/manager";
    process = fork();
    if (process == 0) {
      if (in_manager) {
        execlp("rosrun", "rosrun", "nodelet", "nodelet", "manager", "__name:=manager", ns_arg.c_str(),
               static_cast<char*>(nullptr));
      } else {
        execl(MILD_NODE_BIN, MILD_NODE_BIN, ns_arg.c_str(), "__name:=mild_lcd", path_arg.c_str(),
              "_save_on_shutdown:=true", "_use_image_input:=false", period_arg.c_str(), static_cast<char*>(nullptr));
      }
      _exit(127);
    }
    if (!in_manager) return;
    loader = fork();
    if (loader == 0) {
      execlp("rosrun", "rosrun", "nodelet", "nodelet", "load", "mild_lcd/LoopClosureNodelet", manager_name.c_str(),
             ns_arg.c_str(), "__name:=mild_lcd", path_arg.c_str(), "_save_on_shutdown:=true", "_use_image_input:=false",
             period_arg.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
  }
  // Feeds `count` keyframes and waits for their answers; returns how many were answered.
  static size_t feed(const std::string& ns, int count) {
    ros::NodeHandle nh;
    ros::Publisher keyframes = nh.advertise<mild_lcd::Keyframe>(ns + "/keyframe", 100);
    TopicLog<mild_lcd::LoopClosure> outputs(ns + "/loop_closure");
    EXPECT_TRUE(outputs.waitForPublisher(30.0));
    EXPECT_TRUE(waitForSubscriber(keyframes, 30.0));
    cv::RNG rng(3);
    for (int i = 0; i < count; ++i) {
      mild_lcd::Keyframe kf;
      kf.header.stamp = ros::Time(3000.0 + i);
      kf.keypoints.resize(50);
      for (auto& p : kf.keypoints) p.x = p.y = static_cast<float>(rng.uniform(0, 200));
      kf.descriptors.resize(50 * 32);
      for (auto& b : kf.descriptors) b = static_cast<uint8_t>(rng.uniform(0, 256));
      keyframes.publish(kf);
    }
    EXPECT_TRUE(outputs.waitForCount(static_cast<size_t>(count), 30.0));
    return outputs.size();
  }
  // Sends `signal` to the manager or node; true when it exited within `timeout_s`.
  bool stop(int signal, double timeout_s) { return stopProcess(process, signal, timeout_s); }

  ~RunningNode() {
    for (pid_t* pid : {&loader, &process}) {
      if (*pid > 0 && !stopProcess(*pid, SIGINT, 20.0)) stopProcess(*pid, SIGKILL, 20.0);
    }
  }

 private:
  static bool stopProcess(pid_t& pid, int signal, double timeout_s) {
    kill(pid, signal);
    const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout_s);
    int status = 0;
    while (ros::WallTime::now() < end) {
      if (waitpid(pid, &status, WNOHANG) == pid) {
        pid = -1;
        return true;
      }
      ros::WallDuration(0.05).sleep();
    }
    return false;
  }
};

// SIGINT (Ctrl-C, roslaunch) and SIGTERM (docker stop, systemd's default KillSignal, kill) stop the
// standalone node and a nodelet manager in order: the map is saved. A nodelet manager does not
// handle SIGTERM itself: it used to end at once, its nodelets never unloaded, nothing was saved.
TEST(Persistence, SigintAndSigtermSaveTheMapInANodeletManagerAndTheNode) {
  fs::create_directories(scratch());
  for (const bool in_manager : {true, false}) {
    for (const int signal : {SIGTERM, SIGINT}) {
      const std::string what = std::string(in_manager ? "manager" : "node") + (signal == SIGTERM ? "_term" : "_int");
      const std::string map = (scratch() / (what + ".mild")).string();
      fs::remove(map);
      RunningNode node("/" + what, map, 0, in_manager);  // no periodic save: the map must come from the stop
      ASSERT_EQ(RunningNode::feed("/" + what, 3), 3u) << what;
      EXPECT_FALSE(fs::exists(map)) << what << ": nothing saved before the signal";
      ASSERT_TRUE(node.stop(signal, 20.0)) << what << " did not stop";
      ASSERT_TRUE(fs::exists(map)) << what << " stopped and did not save";
      EXPECT_EQ(mild::readMapFile(map).records.size(), 3u) << what;
    }
  }
}

// SIGKILL cannot be handled: with ~save_on_shutdown the map is also saved every ~autosave_period
// seconds when it changed, so at most that period is lost.
TEST(Persistence, AutosaveBoundsWhatSigkillLoses) {
  fs::create_directories(scratch());
  const std::string map = (scratch() / "sigkill.mild").string();
  fs::remove(map);
  RunningNode node("/sigkill", map, 1, true);
  ASSERT_EQ(RunningNode::feed("/sigkill", 5), 5u);
  size_t saved = 0;
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(30.0);
  while (saved < 5 && ros::WallTime::now() < end) {
    ros::WallDuration(0.2).sleep();
    try {
      saved = fs::exists(map) ? mild::readMapFile(map).records.size() : 0;
    } catch (const std::exception&) {
      saved = 0;  // never half a file: saves are renamed into place; an error here is a failure below
    }
  }
  EXPECT_EQ(saved, 5u) << "no periodic save within 30 s of a 1 s period";
  ASSERT_TRUE(node.stop(SIGKILL, 20.0));
  ASSERT_TRUE(fs::exists(map));
  EXPECT_EQ(mild::readMapFile(map).records.size(), 5u) << "what the last periodic save held";
}

// A corrupt map at start-up: the node says why (naming the file), refuses keyframes rather than
// learning a new map on nothing, and does not write over the file when it stops. Issue 49 item 1:
// nor after the user loads another map by hand (an empty one here): keyframes are taken again, but
// neither the periodic save (every second here) nor the save on shutdown writes over the map that
// was refused, and a save_database without a path is refused; only one naming it would write it.
TEST(Persistence, AMapThatFailsToLoadAtStartUpIsNeverOverwritten) {
  fs::create_directories(scratch());
  const std::string corrupt = (scratch() / "corrupt_start.mild").string();
  const std::string text = "definitely not a database";
  std::ofstream(corrupt) << text;
  {
    mild::LoopDetector empty;
    mild::saveMap(empty.map(), (scratch() / "empty_by_hand.mild").string());
  }
  const std::string log = (scratch() / "broken_map.log").string();
  const pid_t pid = fork();
  if (pid == 0) {
    const std::string path_arg = "_database_path:=" + corrupt;
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1);
    dup2(fd, 2);
    execl(MILD_NODE_BIN, MILD_NODE_BIN, "__ns:=/broken_map", "__name:=mild_lcd", path_arg.c_str(),
          "_load_on_start:=true", "_save_on_shutdown:=true", "_autosave_period:=1", "_use_image_input:=false",
          static_cast<char*>(nullptr));
    _exit(127);
  }
  ASSERT_GT(pid, 0);
  {
    ros::NodeHandle nh;
    ros::Publisher keyframes = nh.advertise<mild_lcd::Keyframe>("/broken_map/keyframe", 10);
    TopicLog<mild_lcd::LoopClosure> outputs("/broken_map/loop_closure");
    ASSERT_TRUE(outputs.waitForPublisher(30.0));
    ASSERT_TRUE(waitForSubscriber(keyframes, 30.0));
    mild_lcd::Keyframe kf;
    kf.keypoints.resize(1);
    kf.descriptors.assign(32, 0x3C);
    for (int i = 0; i < 3; ++i) keyframes.publish(kf);
    ros::WallDuration(2.0).sleep();
    EXPECT_EQ(outputs.size(), 0u) << "keyframes are refused while the start-up map is not loaded";
    mild_lcd::SaveDatabase::Request save;
    EXPECT_FALSE(call<mild_lcd::SaveDatabase>("/broken_map/save_database", save).response.success)
        << "nor saved through the service";

    mild_lcd::LoadDatabase::Request load;
    load.path = "empty_by_hand.mild";
    const auto loaded = call<mild_lcd::LoadDatabase>("/broken_map/load_database", load);
    ASSERT_TRUE(loaded.response.success) << loaded.response.message;
    for (int i = 0; i < 3; ++i) {
      kf.header.stamp = ros::Time(10.0 + i);
      keyframes.publish(kf);
    }
    EXPECT_TRUE(outputs.waitForCount(3, 20.0)) << "keyframes are taken once a map is loaded by hand";
    ros::WallDuration(3.0).sleep();  // three autosave periods
    EXPECT_EQ(fs::file_size(corrupt), text.size()) << "the periodic save wrote over the map refused at start-up";
    const auto refused = call<mild_lcd::SaveDatabase>("/broken_map/save_database", save);
    EXPECT_FALSE(refused.response.success) << "a save without a path would replace the map refused at start-up";
    EXPECT_NE(refused.response.message.find("protected"), std::string::npos) << refused.response.message;
  }
  kill(pid, SIGINT);
  int status = 0;
  waitpid(pid, &status, 0);
  std::ifstream in(log);
  const std::string output((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(output.find(corrupt), std::string::npos) << output;
  EXPECT_NE(output.find("not a mild_lcd database"), std::string::npos) << output;
  EXPECT_NE(output.find("not saving on shutdown"), std::string::npos) << output;
  EXPECT_EQ(fs::file_size(corrupt), text.size()) << "the file is left for inspection";
}

// SIGINT with a long queue: what waits is dropped (counted, logged), what was processed is saved,
// well inside the 15 s roslaunch gives a node before it escalates to SIGTERM.
TEST(Persistence, ShutdownWithAFullQueueSavesWhatWasProcessedInTime) {
  fs::create_directories(scratch());
  const std::string map = (scratch() / "busy.mild").string();
  const pid_t pid = fork();
  if (pid == 0) {
    const std::string path_arg = "_database_path:=" + map;
    execl(MILD_NODE_BIN, MILD_NODE_BIN, "__ns:=/busy", "__name:=mild_lcd", path_arg.c_str(), "_save_on_shutdown:=true",
          "_use_image_input:=false", "_queue_size:=5000", static_cast<char*>(nullptr));
    _exit(127);
  }
  ASSERT_GT(pid, 0);
  size_t answered = 0;
  {
    ros::NodeHandle nh;
    ros::Publisher keyframes = nh.advertise<mild_lcd::Keyframe>("/busy/keyframe", 5000);
    TopicLog<mild_lcd::LoopClosure> outputs("/busy/loop_closure", 5000);
    ASSERT_TRUE(outputs.waitForPublisher(30.0));
    ASSERT_TRUE(waitForSubscriber(keyframes, 30.0));
    cv::RNG rng(11);
    for (int i = 0; i < 2000; ++i) {  // far more than the node processes in the second it is given
      mild_lcd::Keyframe kf;
      kf.header.stamp = ros::Time(100.0 + i);
      kf.keypoints.resize(800);
      kf.descriptors.resize(800 * 32);
      for (auto& b : kf.descriptors) b = static_cast<uint8_t>(rng.uniform(0, 256));
      keyframes.publish(kf);
    }
    ASSERT_TRUE(outputs.waitForCount(5, 60.0));
    ros::WallDuration(0.5).sleep();
    const auto start = ros::WallTime::now();
    kill(pid, SIGINT);
    int status = 0;
    waitpid(pid, &status, 0);
    EXPECT_LT((ros::WallTime::now() - start).toSec(), 10.0) << "inside roslaunch's 15 s";
    answered = outputs.size();
  }
  ASSERT_TRUE(fs::exists(map));
  const size_t saved = mild::readMapFile(map).records.size();
  EXPECT_GE(saved, answered) << "every answered keyframe is in the saved map";
  EXPECT_LT(saved, 2000u) << "the queue was not worked off before saving";
}

// nodelet_hubness.test: filter/hubness_min_queries from the parameter server reaches the filter; the
// saved map names the hub-corrected filter and holds its state (the test before it found the loops).
TEST(HubCorrection, TheSavedMapHoldsTheHubCorrectedFilter) {
  mild_lcd::SaveDatabase::Request save;
  save.path = (scratch() / "hubness.mild").string();
  const auto saved = call<mild_lcd::SaveDatabase>("save_database", save);
  ASSERT_TRUE(saved.response.success) << saved.response.message;
  const mild::MapState contents = mild::readMapFile(save.path);
  EXPECT_EQ(contents.filter_name, "exclusive_hypotheses+hubness");
  EXPECT_GT(contents.filter_state.size(), mild::KeyframeHubness::stateBytes(contents.records.size() / 2));
}

}  // namespace
}  // namespace mild_lcd::test
