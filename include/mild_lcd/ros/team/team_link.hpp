#pragma once

// A station of a team across hosts (~team/station) on ROS topics: the protocol is mild::Station's
// (team/station.hpp: numbering, gaps, resends, pulls, what is refused); this link subscribes,
// converts, signs and checks the team key's MAC, and sends what the station says on its own thread.
// Design and figures: docs/multi_robot.md, "Stations on several hosts".
//
// Every message is topic traffic (no service calls, which could block on a dead link and need one
// master): relaying /mild_team/ between masters gives the same behaviour. Each message's size and
// type are checked before it is deserialised. Team key (~team/key_file): every message sent carries
// a counter and an HMAC-SHA256 under the key over its topic and content; one received without a
// valid MAC, or not above its sender's last counter on its topic, is refused before it is read.
// With a roster (~team/roster_dir, ~team/station_key_file), it also carries its sender's Ed25519
// signature, checked against the roster's key for the station it names.

#include <atomic>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/ros/detection/shared_detector.hpp"
#include "mild_lcd/ros/settings/node_settings.hpp"
#include "mild_lcd/team/station.hpp"
#include "mild_lcd/team/station_identity.hpp"

namespace mild_lcd {

class TeamLink : private mild::StationMaps {
 public:
  // Publishes a loop on each of these robots' loop_closure (and once on loop_closures_all).
  using PublishLoop = std::function<void(const std::vector<size_t>& robots, const mild_lcd::LoopClosure::ConstPtr&)>;

  // The keys, read at start(): the team key (~team/key_file; empty: none, and anyone who can publish
  // on /mild_team/ can inject loops: warned about at start-up and in diagnostics), and this
  // station's private key and the team's roster of public keys (both or neither: names bound).
  struct KeyFiles {
    std::string team, station, roster;
  };

  // ledger_path: where the ledger is saved beside the maps (empty: never). Throws InvalidInput for a
  // bad station name.
  TeamLink(ros::NodeHandle nh, const NodeSettings& settings, SharedDetector& shared,
           std::vector<std::string> robot_names, std::string ledger_path, KeyFiles keys, PublishLoop publish);
  ~TeamLink() override;

  // After the maps were loaded: reads the key and the ledger when its file exists (a restart),
  // subscribes and starts the thread. Throws IoError/InvalidInput for an unreadable ledger or key
  // (a key file others can read is refused).
  void start();
  // Waits a moment for open pulls and acknowledgements, unsubscribes and joins the thread.
  void stop();
  // Writes the ledger (the maps' crash-safe writer) when a path was given and the link started.
  void save();
  // Under the detector lock, right after a keyframe was stored: numbered, summarised and sent.
  void stored(const mild::DetectionResult& result);
  // Under the detector lock: robot's map was replaced.
  void mapReplaced(size_t robot) { station_.mapReplaced(robot); }
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);

 private:
  std::unique_lock<std::mutex> lock() override { return shared_.lock(); }
  mild::RobotTeam& team() override { return *shared_.team; }
  uint64_t replaced() const override { return shared_.replaced; }

  void run();
  void send(mild::Outbox out);
  void persist();  // save() after a loop was decided or taken (with ~save_on_shutdown)
  template <class M>
  void sign(M& msg, const std::string& topic);
  template <class M>
  bool authentic(const M& msg, const std::string& topic) const;
  template <class M>
  void sendTo(const std::string& peer, const std::string& name, M msg);
  template <class M>
  ros::Subscriber subscribe(const std::string& name, uint32_t queue, uint64_t max_bytes,
                            std::function<void(const M&)> handle);

  ros::NodeHandle nh_;
  const NodeSettings settings_;
  SharedDetector& shared_;
  const std::string ledger_path_;
  const KeyFiles key_files_;
  PublishLoop publish_;
  mild::Station station_;
  mild::TeamCredentials credentials_;   // read at start(), then only read
  std::atomic<uint64_t> next_counter_;  // messages sent: from the wall clock's ns at construction
  std::mutex lifecycle_;                // start() and stop(), one at a time
  bool stopped_ = false;                // under lifecycle_
  std::atomic<bool> started_{false};
  std::map<std::string, std::map<std::string, ros::Publisher>> to_;  // per peer, per inbox (thread only)
  ros::Publisher summaries_pub_, status_pub_;
  // The team's messages are handled on a queue and thread of their own: a flood of them (forged, or
  // a peer catching up) never waits in front of the robots' keyframes on the nodelet's threads.
  ros::CallbackQueue queue_;
  std::unique_ptr<ros::AsyncSpinner> spinner_;
  std::vector<ros::Subscriber> subscribers_;
  std::thread thread_;
};

}  // namespace mild_lcd
