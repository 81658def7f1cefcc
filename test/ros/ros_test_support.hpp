#pragma once

// Helpers shared by the rostest nodes: collecting what the nodelet publishes, playing a bag with
// the real `rosbag play`, reading the test's private parameters.

#include <gtest/gtest.h>

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

}  // namespace mild_lcd::test
