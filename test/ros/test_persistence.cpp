// rostest cases for the database file through ROS: save_database / load_database services, and
// the ~database_path, ~load_on_start, ~save_on_shutdown parameters of a node started and stopped
// here. Part of test_nodelet (main() is there); selected by test/ros/nodelet_persistence.test.

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <set>

#include <cv_bridge/cv_bridge.h>
#include <opencv2/imgcodecs.hpp>
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <std_srvs/Trigger.h>

#include "../common/run_command.hpp"
#include "mild_lcd/Keyframe.h"
#include "mild_lcd/LoadDatabase.h"
#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/SaveDatabase.h"
#include "mild_lcd/database_file.hpp"
#include "mild_lcd/evaluation.hpp"
#include "ros_test_support.hpp"

namespace fs = std::filesystem;

namespace mild_lcd::test {
namespace {

const std::string kFixtureDir = std::string(MILD_SOURCE_DIR) + "/test/data/corridor_stride5";

fs::path scratch() {
  static const fs::path dir = [] {
    const fs::path d = fs::temp_directory_path() / ("mild_persistence_" + std::to_string(::getpid()));
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
    images.publish(cv_bridge::CvImage(header, sensor_msgs::image_encodings::MONO8, cv::imread(files[i], cv::IMREAD_GRAYSCALE))
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
  EXPECT_EQ(mild::readDetectorFile(map).records.size(), 47u);

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
      if (c.probability < 0.5) continue;
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
  save.path = (scratch() / "no" / "such" / "dir.mild").string();
  EXPECT_FALSE(call<mild_lcd::SaveDatabase>("save_database", save).response.success);
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
  const size_t stored = mild::readDetectorFile(map).records.size();

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
  EXPECT_EQ(mild::readDetectorFile(map).records.size(), stored + 1) << "saved on shutdown";

  // A corrupt map at start-up stops the node, naming the file, rather than starting empty and
  // overwriting it on shutdown.
  const std::string corrupt = (scratch() / "corrupt_start.mild").string();
  std::ofstream(corrupt) << "definitely not a database";
  const auto run = mild::test::runCommand(std::string("timeout 30 ") + MILD_NODE_BIN + " __ns:=/broken_map __name:=mild_lcd "
                                          "_database_path:=" + corrupt +
                                          " _load_on_start:=true _save_on_shutdown:=true _use_image_input:=false");
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.status, 124) << "kept running on a corrupt map";
  EXPECT_NE(run.output.find(corrupt), std::string::npos) << run.output;
  EXPECT_EQ(fs::file_size(corrupt), std::string("definitely not a database").size()) << "the file is left for inspection";
  fs::remove_all(scratch());
}

}  // namespace
}  // namespace mild_lcd::test
