#pragma once

// A station of a team across hosts (~team/station): this node's robots' maps answer the other
// stations' keyframes, and theirs answer ours, while running. Design and figures:
// docs/multi_robot.md, "Stations on several hosts".
//
// - Push: every keyframe stored here is summarised (its strongest descriptors, PlaceSummary) and
//   published once on /mild_team/summaries.
// - Decide: a peer's summary is asked of this station's maps (RobotTeam::askRemote) where the
//   StationLedger says this station decides. When a candidate could be accepted, the keyframe's
//   whole features are pulled from its station (/mild_team/<peer>/requests, answered on
//   /mild_team/<this>/features, refusable when busy) and the candidates verified and scored as the
//   station's own. An accepted loop is published on the map robot's loop_closure here, and sent to
//   the query's station (/mild_team/<peer>/loops), numbered, resent until acknowledged, which
//   publishes it on the query robot's loop_closure: once on each side.
// - Links drop: summaries are taken from each peer in their order only; a gap (a summary lost,
//   a heartbeat announcing more) is asked for in batches (~team/backfill_batch) until filled, so a
//   revisit made during an outage is found when the link is back ("late", counted). Nothing waits
//   for a peer: the robots' own keyframes go through the worker as always; peer work is done on
//   this link's own thread, and holds the detector lock only to query, judge and serve.
// - Every message is topic traffic (no service calls, which could block on a dead link and need
//   one master): relaying /mild_team/ between masters gives the same behaviour.
// - Team key (~team/key_file): every message sent carries a counter and an HMAC-SHA256 under the
//   key; one received without a valid MAC, or not above its sender's last counter on its topic, is
//   refused before it is read, and counted against its claimed sender. Without a key: warned about.
// - Hostile peers: malformed, oversized or other-width messages are refused and counted; more than
//   ~team/max_requests_per_second requests from one peer are refused as busy; unknown keyframes
//   get UNKNOWN. Every inbox is bounded.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/PlaceSummary.h"
#include "mild_lcd/TeamFeatures.h"
#include "mild_lcd/TeamLoop.h"
#include "mild_lcd/TeamRequest.h"
#include "mild_lcd/TeamStatus.h"
#include "mild_lcd/detector/robot_team.hpp"
#include "mild_lcd/ros/detection/shared_detector.hpp"
#include "mild_lcd/ros/settings/node_settings.hpp"
#include "mild_lcd/team/station_ledger.hpp"
#include "mild_lcd/team/team_key.hpp"

namespace mild_lcd {

class TeamLink {
 public:
  // Publishes a loop on each of these robots' loop_closure (and once on loop_closures_all).
  using PublishLoop = std::function<void(const std::vector<size_t>& robots, const mild_lcd::LoopClosure::ConstPtr&)>;

  // nh: the node's namespace handle (topics go under /mild_team/, absolute). ledger_path: where
  // the ledger is saved beside the maps (empty: never). Throws InvalidInput for a bad station name.
  // key_file: the team key (~team/key_file), read at start(); empty: no key, and anyone who can
  // publish on /mild_team/ can inject loops (warned about at start-up and in diagnostics).
  TeamLink(ros::NodeHandle nh, const NodeSettings& settings, SharedDetector& shared,
           std::vector<std::string> robot_names, std::string ledger_path, std::string key_file, PublishLoop publish);
  ~TeamLink();

  // After the maps were loaded: reads the team key and the ledger when its file exists (a restart),
  // subscribes and starts the link's thread. Throws IoError/InvalidInput for an unreadable ledger or
  // key (a key file others can read is refused).
  void start();
  // Unsubscribes and joins the thread; what waits is kept in the ledger's counts (asked again).
  void stop();
  // Writes the ledger (atomically) when a path was given and the link started (a link that could
  // not read its ledger never writes over it). Under no lock; takes the detector's.
  void save();
  // save() after a loop was decided or taken, before it is published: a crash after does not make it
  // again (with ~save_on_shutdown; a failure is warned about).
  void persist();

  // Under the detector lock, right after a keyframe was stored: numbered and summarised.
  void stored(const mild::DetectionResult& result);
  // Under the detector lock: robot's map was replaced.
  void mapReplaced(size_t robot);

  // One key-value per peer and figure, for diagnostics.
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat);

 private:
  struct Waiting {  // a summary received ahead of its turn
    mild_lcd::PlaceSummary::ConstPtr summary;
    bool late = false;  // sent to fill a gap, or numbered during an outage: a loop it gives is found late
  };
  struct Peer {
    std::chrono::steady_clock::time_point last_seen{};
    bool seen = false;
    bool compatible = true;                                  // its descriptors have this station's width
    uint64_t summaries = 0;                                  // it has numbered, by its last heartbeat
    uint64_t acknowledged = 0;                               // loops of ours it took, by its last heartbeat
    mild::PeerRuns runs;                                     // its runs heard (epochs), as the ledger's
    uint64_t loops_from = 0;                                 // the lowest number of its loops for us it can still send
    std::chrono::steady_clock::time_point backfill_asked{};  // the last gap request
    uint64_t taken = 0;   // its summaries taken (the ledger's count, readable under mutex_)
    double tokens = 0.0;  // its requests' budget (refilled per second)
    std::chrono::steady_clock::time_point refilled{};
    std::map<uint64_t, Waiting> waiting;  // by number: the next to take, and any ahead of a gap
    struct Sent {
      mild_lcd::TeamLoop::ConstPtr loop;
      std::chrono::steady_clock::time_point at{};
    };
    std::deque<Sent> unacknowledged;  // loops sent, by number, until its heartbeat counts them
    size_t pending_pulls = 0;
    uint64_t summaries_in = 0, summary_bytes_in = 0, features_in = 0, feature_bytes_in = 0;
    uint64_t bytes_out = 0, loops_decided = 0, loops_found_late = 0, refused = 0, duplicates = 0, reconnects = 0;
    uint64_t loops_lost = 0;  // its loops for us it could no longer send (its restart, or crash)
    ros::Publisher to_requests, to_summaries, to_features, to_loops;  // to its inbox
    bool advertised = false;                                          // the four above exist (advertiseNewPeers)
  };
  struct Pending {  // a peer's keyframe waiting for its features
    std::string peer;
    mild_lcd::PlaceSummary::ConstPtr summary;
    mild::RobotTeam::RemoteAnswer answer;
    uint64_t replaced = 0;  // SharedDetector::replaced when asked
    bool late = false;
    std::chrono::steady_clock::time_point asked{};
    int attempts = 0;
  };

  void run();
  void tick();               // heartbeat, gap requests, resends: once a second
  void advertiseNewPeers();  // the inbox topics of peers seen since (on the thread: never under mutex_)
  bool takeNextSummary();
  void take(const std::string& peer, const mild_lcd::PlaceSummary::ConstPtr& summary, bool late);
  void judged(const Pending& pending, const mild::Features* features);
  void serve(const mild_lcd::TeamRequest::ConstPtr& request);
  void onFeatures(const mild_lcd::TeamFeatures::ConstPtr& reply);
  void onLoop(const mild_lcd::TeamLoop::ConstPtr& loop);
  std::string unknownKeyframeOf(const mild_lcd::TeamLoop& loop, size_t robot) const;
  void sendPull(uint64_t request_id, Pending& pending);

  void onSummary(const mild_lcd::PlaceSummary::ConstPtr& msg);
  void onBackfill(const mild_lcd::PlaceSummary::ConstPtr& msg);
  void queueSummary(const mild_lcd::PlaceSummary::ConstPtr& msg, bool backfill);
  static bool seeRun(Peer& p, uint64_t epoch, uint64_t start);
  void onStatus(const mild_lcd::TeamStatus::ConstPtr& msg);
  void onRequest(const mild_lcd::TeamRequest::ConstPtr& msg);
  void onFeaturesMsg(const mild_lcd::TeamFeatures::ConstPtr& msg);
  void onLoopMsg(const mild_lcd::TeamLoop::ConstPtr& msg);
  // Numbers and, with a key, authenticates `msg` for `topic`; then publishes it there (when advertised).
  template <class M>
  void sign(M& msg, const std::string& topic);
  template <class M>
  void sendTo(const ros::Publisher& to, M& msg);
  // Whether `msg`, arrived on `topic`, carries a valid MAC under the team key and a counter above the
  // last of its sender's there (always, without a key); else it is counted against its claimed sender.
  template <class M>
  bool authentic(const M& msg, const std::string& topic, const std::string& sender);
  template <class M>
  ros::Subscriber subscribeBounded(const std::string& name, uint32_t queue, uint64_t max_bytes,
                                   void (TeamLink::*handle)(const typename M::ConstPtr&));
  // Into a bounded inbox for the link's thread; a full one refuses (counted).
  template <class Ptr>
  void queue(std::deque<Ptr>& inbox, const Ptr& msg);

  // Under mutex_: the peer by name, made on first sight (at most kMaxPeers), or nullptr.
  Peer* peer(const std::string& name);
  bool connected(const Peer& p) const;
  mild_lcd::PlaceSummary::Ptr summaryOf(uint64_t seq);  // under the detector lock
  size_t robotIndex(const std::string& name) const;     // robot_names_.size() when unknown

  static constexpr size_t kMaxPeers = 64;
  static constexpr size_t kMaxInbox = 1000;  // requests, replies and loops waiting for the thread

  ros::NodeHandle nh_;
  const NodeSettings settings_;
  SharedDetector& shared_;
  const std::vector<std::string> robot_names_;
  const std::string ledger_path_;
  const std::string key_file_;
  std::optional<mild::TeamKey> key_;    // read at start(), then only read
  std::atomic<uint64_t> next_counter_;  // messages this station sent: from the wall clock's ns at start
  PublishLoop publish_;
  mild::StationLedger ledger_;  // under the detector lock
  size_t summary_descriptors_ = 0;
  int descriptor_bytes_ = 0;

  std::mutex mutex_;  // everything below; never held while taking the detector lock
  std::condition_variable wake_;
  bool stopping_ = false;
  std::mutex lifecycle_;   // start() and stop(), one at a time
  bool stopped_ = false;   // stop() ran: start() does nothing (under lifecycle_)
  bool draining_ = false;  // stop(): no more peer keyframes taken, the open pulls answered
  std::map<std::string, Peer> peers_;
  std::deque<mild_lcd::TeamRequest::ConstPtr> requests_;
  std::deque<mild_lcd::TeamFeatures::ConstPtr> replies_;
  std::deque<mild_lcd::TeamLoop::ConstPtr> loops_;
  std::map<uint64_t, Pending> pending_;              // by request id
  std::map<std::string, uint32_t> remote_sessions_;  // per remote robot: its last summary's session (thread only)
  uint64_t next_request_ = 1;
  uint64_t refused_ = 0;         // from no peer (malformed names, too many peers, full inboxes)
  uint64_t refused_unread_ = 0;  // of them, refused before deserialising (oversized, or another type)
  // With a team key: messages without a valid MAC, or replayed, per claimed sender (the first
  // kMaxPeers names; the others under ""), and the last counter taken per sender and topic.
  std::map<std::string, uint64_t> unauthenticated_;
  std::map<std::string, uint64_t> last_counter_;
  uint64_t inbox_bytes_ = 0;  // of requests_, replies_ and loops_
  uint64_t summary_bytes_out_ = 0, summaries_out_ = 0;
  uint64_t epoch_ = 0;  // this run's (StationLedger::beginRun), set at start()

  ros::Publisher summaries_pub_, status_pub_;
  ros::Subscriber summaries_sub_, backfill_sub_, status_sub_, requests_sub_, features_sub_, loops_sub_;
  std::thread thread_;
  std::atomic<bool> started_{false};  // start() succeeded: keyframes are numbered, the ledger saved
};

}  // namespace mild_lcd
