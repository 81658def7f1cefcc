#pragma once

// Helpers shared by the rostest nodes: collecting what the nodelet publishes, playing a bag with
// the real `rosbag play`, reading the test's private parameters.

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <condition_variable>
#include <cstdlib>
#include <mutex>
#include <string>
#include <vector>

#include <ros/ros.h>

namespace mild_lcd::test {

inline std::string privateParam(const std::string& name, const std::string& fallback = "") {
  std::string value;
  ros::NodeHandle("~").param(name, value, fallback);
  return value;
}

// Every message of one topic, in arrival order.
template <class Msg>
class TopicLog {
 public:
  explicit TopicLog(const std::string& topic, uint32_t queue = 1000) {
    sub_ = ros::NodeHandle().subscribe<Msg>(topic, queue, [this](const boost::shared_ptr<const Msg>& m) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        messages_.push_back(*m);
      }
      arrived_.notify_all();
    });
  }

  // Waits until at least n messages have arrived; false on timeout.
  bool waitForCount(size_t n, double timeout_s) {
    std::unique_lock<std::mutex> lock(mutex_);
    return arrived_.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] { return messages_.size() >= n; });
  }

  // Waits until the subscription is connected to a publisher.
  bool waitForPublisher(double timeout_s) const {
    const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout_s);
    while (sub_.getNumPublishers() == 0 && ros::WallTime::now() < end) ros::WallDuration(0.05).sleep();
    return sub_.getNumPublishers() > 0;
  }

  std::vector<Msg> messages() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return messages_;
  }
  size_t size() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return messages_.size();
  }
  void clear() {
    std::lock_guard<std::mutex> lock(mutex_);
    messages_.clear();
  }

 private:
  ros::Subscriber sub_;
  mutable std::mutex mutex_;
  std::condition_variable arrived_;
  std::vector<Msg> messages_;
};

// Waits until a publisher of ours has a subscriber (the nodelet).
template <class Publisher>
bool waitForSubscriber(const Publisher& pub, double timeout_s) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(timeout_s);
  while (pub.getNumSubscribers() == 0 && ros::WallTime::now() < end) ros::WallDuration(0.05).sleep();
  return pub.getNumSubscribers() > 0;
}

// Plays one topic of a bag with `rosbag play` (the real player, against this test's master) once the
// nodelet subscribes to it. `rate_args` is e.g. "-r 4" or "--immediate". Returns the exit status.
inline int playBag(const std::string& bag, const std::string& topic, const std::string& rate_args) {
  const std::string command = "rosbag play --quiet --wait-for-subscribers " + rate_args + " '" + bag + "' --topics " +
                              topic + " > /dev/null 2>&1";
  return std::system(command.c_str());
}

// `rosbag play` kept alive past the end of the bag (--keep-alive) until this object goes: a player
// that exits right after publishing (as --immediate does with a backlog in its sockets) takes the
// messages it has not yet written with it, on a loaded machine the last few of the bag.
class KeptAliveBagPlayer {
 public:
  KeptAliveBagPlayer(const std::string& bag, const std::string& topic, const std::string& rate_args) {
    const std::string command = "exec rosbag play --quiet --wait-for-subscribers --keep-alive " + rate_args + " '" +
                                bag + "' --topics " + topic + " > /dev/null 2>&1";
    pid_ = ::fork();
    if (pid_ == 0) {
      ::execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
  }
  KeptAliveBagPlayer(const KeptAliveBagPlayer&) = delete;
  KeptAliveBagPlayer& operator=(const KeptAliveBagPlayer&) = delete;
  ~KeptAliveBagPlayer() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGINT);
    int status = 0;
    for (int i = 0; i < 100 && ::waitpid(pid_, &status, WNOHANG) == 0; ++i) ::usleep(50000);
    if (::waitpid(pid_, &status, WNOHANG) == 0) {  // still there after 5 s
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, &status, 0);
    }
  }
  bool started() const { return pid_ > 0; }

 private:
  pid_t pid_ = -1;
};

}  // namespace mild_lcd::test
