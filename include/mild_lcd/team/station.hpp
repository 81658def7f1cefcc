#pragma once

// The station protocol of a team across hosts, without ROS (docs/multi_robot.md, "Stations on
// several hosts"). A Station takes the messages its peers sent (plain structs, team_messages.hpp)
// and says what to send and publish (an Outbox); the link (ros/team/team_link.hpp) only converts,
// signs, checks MACs and moves bytes. What it owns:
//
// - Push: every keyframe stored here is numbered (StationLedger) and summarised (stored()).
// - Decide: a peer's summaries are taken in their order only, per run of that peer (its epoch);
//   each is asked of this station's maps (RobotTeam::askRemote) where the ledger says this station
//   decides. When a candidate could be accepted, the keyframe's whole features are pulled from its
//   station (refusable when busy), and the candidates verified and scored as the station's own. An
//   accepted loop is published here and sent to the query's station, numbered per run, resent until
//   acknowledged: published once on each side. Loops are held by content (StationLedger::keepLoop):
//   one decided again after a crash is neither sent nor published again.
// - Links drop: a gap (a summary lost, a heartbeat announcing more) is asked for in batches until
//   filled; a loop found for a keyframe numbered during an outage is counted late.
// - Hostile peers: every message is bounded and checked; a peer's loop is published only when its
//   query is a keyframe stored here, its candidates keyframes its decider announced and its
//   content sound (peer_loop_check.hpp, on arrival), `accepted` decided here; a name never heard
//   from makes no peer; more than max_requests_per_second requests from one peer are answered
//   busy; with a team key, messages whose MAC fails or that replay a counter are refused and
//   counted per claimed sender.
//
// Threads: arrivals (receive*, admit) only queue, under the station's own lock; work() runs on the
// link's thread; stored() and mapReplaced() on the keyframe path, under the detector lock. Lock
// order: the detector's (StationMaps::lock), then the station's; never the other way.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "mild_lcd/detector/robot_team.hpp"
#include "mild_lcd/team/peer_loop_check.hpp"
#include "mild_lcd/team/place_summary.hpp"
#include "mild_lcd/team/station_ledger.hpp"
#include "mild_lcd/team/team_messages.hpp"

namespace mild {

// What a station asks of the detector it serves: its lock, its robots' maps under it, and a count
// bumped whenever a map's keyframes are replaced (a load, a merge, a reset).
class StationMaps {
 public:
  virtual ~StationMaps() = default;
  virtual std::unique_lock<std::mutex> lock() = 0;
  virtual RobotTeam& team() = 0;          // under lock()
  virtual uint64_t replaced() const = 0;  // under lock()
};

struct StationSettings {
  std::string station;                          // ~team/station
  std::vector<std::string> robots;              // this station's robots as named on the wire
  size_t summary_bytes = kDefaultSummaryBytes;  // ~team/summary_bytes (the same at every station)
  size_t backfill_batch = 20;                   // ~team/backfill_batch
  size_t max_pending_pulls = 32;                // ~team/max_pending_pulls
  double max_requests_per_second = 20.0;        // ~team/max_requests_per_second
  double peer_timeout = 5.0;                    // ~team/peer_timeout, seconds
  size_t max_keyframe_features = 10000;         // ~max_keyframe_features: a pulled keyframe, at most
  // The clock (tests drive their own).
  std::function<std::chrono::steady_clock::time_point()> now = [] { return std::chrono::steady_clock::now(); };
};

// What the link sends and publishes after a call, in this order: the ledger saved first (when
// `persist`: a loop decided or taken is not made again after a crash), then the loops published,
// then the messages.
struct Outbox {
  bool persist = false;
  std::vector<DecidedLoop> published;                           // on the loop's robots' loop_closure here
  std::vector<std::pair<size_t, PeerLoop>> taken;               // a peer's loop, on this robot's loop_closure
  std::vector<DecidedLoop> loops;                               // to each loop's peer
  std::vector<std::pair<std::string, TeamRequest>> requests;    // to the named peer
  std::vector<std::pair<std::string, PlaceSummary>> summaries;  // to the named peer (a gap's filling)
  std::vector<std::pair<std::string, TeamFeatures>> features;   // to the named peer
  std::optional<TeamStatus> status;                             // to every station
  bool empty() const;
};

// One line per figure for diagnostics; warn when a peer is disconnected.
struct StationReport {
  std::vector<std::pair<std::string, std::string>> values;
  bool warn = false;
  std::string summary;
};

class Station {
 public:
  // The largest message any peer may send, and other bounds (each a multiple of an honest one).
  static constexpr size_t kMaxPeers = 64;
  static constexpr size_t kMaxInbox = 1000;  // requests, replies and loops waiting for work()
  static constexpr uint64_t kMaxMessageBytes = 4u << 20;
  static constexpr uint64_t kMaxStatusBytes = 16384;
  static constexpr uint64_t kMaxRequestBytes = 4096;
  static constexpr size_t kMaxNameLength = 64;
  static uint64_t maxSummaryBytes(size_t summary_bytes);

  // Throws InvalidInput for an invalid station name.
  Station(StationSettings settings, StationMaps& maps);
  const StationSettings& settings() const { return settings_; }

  // Before anything else: the ledger saved by an earlier run (none: a first run), the key's
  // presence (messages are then admitted only with a valid MAC), and this run's epoch. Each robot's
  // map gives no id an earlier run may have given (StationLedger::idFloor): save the ledger after
  // this, before the first keyframe. Throws InvalidInput for a ledger of another station or unreadable.
  void start(const std::optional<std::string>& ledger_text, bool keyed, uint64_t epoch = StationLedger::drawEpoch());
  bool started() const { return started_; }
  uint64_t epoch() const { return epoch_; }
  int descriptorBytes() const { return descriptor_bytes_; }  // the maps' width, as of start()
  // The ledger as text (takes the detector lock for a copy of it, not for making the text).
  std::string ledgerText();

  // Under the detector lock, right after a keyframe was stored: its summary to send to every station.
  PlaceSummary stored(const DetectionResult& result);
  // Under the detector lock: robot's map was replaced.
  void mapReplaced(size_t robot);

  // Arrivals (any thread): queued for work(). `backfill`: sent to this station to fill a gap.
  void receive(PlaceSummary summary, bool backfill);
  void receive(const TeamStatus& status, uint64_t wire_bytes);
  void receive(TeamRequest request);
  void receive(TeamFeatures reply);
  void receive(PeerLoop loop);
  // With a key: whether a message of `sender` on `topic` whose MAC is `mac_ok` and counter `counter`
  // is taken (its sender's counters on one topic only grow); else it is counted against `sender`.
  bool admit(const std::string& sender, const std::string& topic, uint64_t counter, bool mac_ok);
  void refusedUnread();  // a message too large or of another type, refused before it was read

  // The link's thread: waits up to `timeout` for something to do; false once halted.
  bool wait(std::chrono::milliseconds timeout);
  // Handles what arrived, takes a bounded batch of peers' summaries, and once a second beats.
  Outbox work();
  // Bytes the link sent to a peer (counted in its figures).
  void sent(const std::string& peer, uint64_t bytes);
  void sentSummary(uint64_t bytes);
  // Peers first seen since the last call (the link makes their topics).
  std::vector<std::string> newPeers();

  // Stopping: no more peer keyframes taken; settled() once no pull waits and no loop waits for a
  // connected peer's acknowledgement; settle() waits up to `timeout` for it (a pull takes
  // milliseconds on a live link), with the link's thread still working. halt() ends wait().
  void drain();
  bool settled();
  bool settle(std::chrono::milliseconds timeout);
  size_t pendingPulls();
  void halt();

  StationReport report();

 private:
  struct Waiting {  // a summary received ahead of its turn
    PlaceSummary summary;
    bool late = false;
  };
  struct Peer {
    std::chrono::steady_clock::time_point last_seen{}, backfill_asked{}, refilled{};
    bool seen = false, compatible = true;
    uint64_t summaries = 0, acknowledged = 0, loops_from = 0;
    uint64_t taken = 0;  // its summaries taken: the ledger's count, readable under mutex_
    PeerRuns runs;
    double tokens = 0.0;
    std::map<uint64_t, Waiting> waiting;
    struct Sent {
      DecidedLoop loop;
      std::chrono::steady_clock::time_point at{};
    };
    std::deque<Sent> unacknowledged;
    size_t pending_pulls = 0;
    uint64_t summaries_in = 0, summary_bytes_in = 0, features_in = 0, feature_bytes_in = 0;
    uint64_t bytes_out = 0, loops_decided = 0, loops_found_late = 0, refused = 0, duplicates = 0, reconnects = 0;
    uint64_t loops_lost = 0;
  };
  struct Pending {  // a peer's keyframe waiting for its features
    std::string peer;
    PlaceSummary summary;
    RobotTeam::RemoteAnswer answer;
    uint64_t replaced = 0;
    bool late = false;
    std::chrono::steady_clock::time_point asked{};
  };

  Peer* peer(const std::string& name);  // under mutex_; made on first sight, or nullptr
  bool connected(const Peer& p) const;
  bool seeRun(Peer& p, uint64_t epoch, uint64_t start);
  bool wellFormed(const PlaceSummary& s) const;
  void refuse(const std::string& name);  // under mutex_: counted against the peer, or no peer
  bool takeNextSummary(Outbox& out);
  void take(const std::string& name, const PlaceSummary& summary, bool late, Outbox& out);
  void sendPull(uint64_t request_id, Pending& pending, Outbox& out);
  void onFeatures(TeamFeatures reply, Outbox& out);
  void judged(const Pending& pending, const Features* features, Outbox& out);
  void onLoop(PeerLoop loop, Outbox& out);
  std::string unknownKeyframeOf(const PeerLoop& loop, size_t robot) const;
  void serve(const TeamRequest& request, Outbox& out);
  void tick(Outbox& out);
  PlaceSummary summaryOf(uint64_t seq);  // under the detector lock
  size_t robotIndex(const std::string& name) const;

  const StationSettings settings_;
  StationMaps& maps_;
  StationLedger ledger_;  // under the detector lock
  size_t summary_descriptors_ = 0;
  int descriptor_bytes_ = 0;
  bool started_ = false, keyed_ = false;
  uint64_t epoch_ = 0;
  std::chrono::steady_clock::time_point next_tick_{};

  std::mutex mutex_;  // everything below
  std::condition_variable wake_;
  bool halted_ = false, draining_ = false;
  bool ids_reserved_ = false;  // a robot's next block of ids: the ledger is to be saved
  PeerLoopRules rules_;        // detector/max_candidates, scoring/decision_probability: as of start() or the last tick
  std::map<std::string, Peer> peers_;
  std::vector<std::string> new_peers_;
  std::deque<TeamRequest> requests_;
  std::deque<TeamFeatures> replies_;
  std::deque<PeerLoop> loops_;
  uint64_t inbox_bytes_ = 0;
  std::map<uint64_t, Pending> pending_;              // by request id
  std::map<std::string, uint32_t> remote_sessions_;  // per remote robot: its last summary's session
  uint64_t next_request_ = 1;
  uint64_t refused_ = 0, refused_unread_ = 0;
  std::map<std::string, uint64_t> unauthenticated_;  // per claimed sender (the first kMaxPeers)
  std::map<std::string, uint64_t> last_counter_;     // per sender and topic
  uint64_t summary_bytes_out_ = 0, summaries_out_ = 0;
};

}  // namespace mild
