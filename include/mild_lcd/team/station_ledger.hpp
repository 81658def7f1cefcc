#pragma once

// What one station of a team across hosts keeps about the others, and why nothing is lost or
// decided twice when links drop (docs/multi_robot.md, "Stations on several hosts"):
// - Its own keyframes are numbered in the order stored (a summary's seq), each with what it knew
//   of every other station then: how many of that station's summaries it held. A peer that missed
//   some asks for them by number and gets them again (the keyframes are in the maps).
// - What it has received from each peer is counted contiguously: the next summary it takes from a
//   peer is the one numbered by that count, so a gap is seen and asked for, never skipped.
// - Which station decides a pair of keyframes of two stations: the one that holds the older of the
//   two in its maps, "older" read from what each knew of the other when it was stored, not from
//   clocks (the hosts' clocks differ). When neither knew of the other (both stored while the link
//   was down, or within one message's flight) the station whose name sorts first decides. Every
//   pair is thus decided by exactly one station, whatever the order summaries arrive in.
// - Loops it decided for a peer's keyframes are numbered per peer and kept until acknowledged.
// - Each run of a station draws a random epoch (beginRun), carried in its messages: a peer keys what
//   it took of a station by (station, epoch, number), so that a run after a crash, numbering from
//   its last saved ledger, never collides with what the crashed run gave (summaryRun, loopRun).
// - Loops are held by content (the query's station, robot, session and id, and the decider): a loop
//   decided again after a crash is a copy whatever its number, and a peer's summary names the
//   stations whose loop for it it holds, so that they do not decide it again (loopedBy).
// It is saved beside the maps so that a restarted station neither re-sends nor re-asks.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "mild_lcd/common/types.hpp"
#include "mild_lcd/team/place_summary.hpp"

namespace mild {

// The runs (epochs) of a peer as heard: the current one and the few before it.
struct PeerRuns {
  enum class Seen { kCurrent, kNew, kPast };
  static constexpr size_t kMaxPast = 16;
  std::optional<uint64_t> current;
  std::vector<uint64_t> past;  // oldest first
  // kNew the first time `epoch` is heard (it becomes current, the one before past); kPast for a run
  // it left (its messages were sent before the restart: dropped).
  Seen see(uint64_t epoch);
};

// A loop as held, by content: its query (its station, robot, session and id) and its decider.
struct LoopKey {
  std::string station, robot;
  uint32_t session = 0;
  uint64_t id = 0;
  std::string decider;
  bool operator<(const LoopKey& o) const;
};

// A station's name: 1 to 32 characters of [a-z0-9_], starting with a letter (it names ROS topics).
bool validStationName(const std::string& name);

class StationLedger {
 public:
  // Throws InvalidInput for an invalid station name or no robots.
  StationLedger(std::string station, size_t robots);

  const std::string& station() const { return station_; }

  // One of this station's keyframes: robot's keyframe `id`, stored at `map_index` of its map, while
  // the stations `unreachable` could not be heard from. Returns its summary's number; what this
  // station knew of each peer is recorded with it.
  uint64_t recordOwn(size_t robot, uint64_t id, KeyframeIndex map_index, std::vector<std::string> unreachable = {});
  uint64_t ownCount() const { return own_.size(); }
  // Own::id of a number taken without a keyframe (a ledger saved by an earlier version, which skipped
  // numbers its peers held after a crash; each run now has an epoch instead): its summary carries nothing.
  static constexpr uint64_t kNoKeyframe = ~uint64_t{0};
  struct Own {
    size_t robot = 0;
    uint64_t id = 0;
    std::vector<std::pair<std::string, uint64_t>> known;  // as PlaceSummary::known
    std::vector<std::string> unreachable;                 // as PlaceSummary::unreachable
  };
  const Own& own(uint64_t seq) const { return own_.at(seq); }

  // The peers' summaries taken so far: the next one taken from `peer` is numbered received(peer).
  uint64_t received(const std::string& peer) const;
  // Counts one more of peer's summaries taken (the one numbered received(peer)).
  void took(const std::string& peer);
  std::vector<std::string> peers() const;

  // A keyframe a peer announced: robot's keyframe `id` of `session` at station `peer`, from a summary
  // taken from it. A loop that peer decides for this station may name only such keyframes as its
  // candidates (they are the peer's own, and it summarises every one it stores).
  void announced(const std::string& peer, const std::string& robot, uint32_t session, uint64_t id);
  bool wasAnnounced(const std::string& peer, const std::string& robot, uint32_t session, uint64_t id) const;

  // How many of robot's map keyframes (of `map_size`) a summary from another station may find as
  // candidates at this station: a prefix of the map. Keyframes stored before the station kept a
  // ledger (earlier sessions, a loaded map) are in it.
  KeyframeIndex eligiblePrefix(size_t robot, KeyframeIndex map_size, const PlaceSummary& summary) const;

  // robot's map was replaced (a load, a reset): its keyframes are no longer the ones numbered.
  // They are all "before the ledger" from now on; the numbers stay taken.
  void mapReplaced(size_t robot);

  // After a restart from maps saved before the ledger (an autosave, then a crash): robot's
  // keyframes numbered at map indices >= map_size are not in its map; they are forgotten (their
  // numbers stay taken: peers may hold their summaries, which then find nothing here).
  void forgetBeyond(size_t robot, KeyframeIndex map_size);

  // Loops this station decided whose query is a peer's keyframe, numbered per peer: the next
  // number, and what the peer acknowledged (it holds loops [0, acknowledged)).
  uint64_t nextLoopFor(const std::string& peer);
  uint64_t loopsSentTo(const std::string& peer) const;
  // Loops a peer decided for this station's keyframes: taken contiguously, as summaries.
  uint64_t loopsReceivedFrom(const std::string& peer) const;
  void tookLoop(const std::string& peer);
  // Counts peer's loops below `count` as taken (the decider can no longer send them: lost), at once.
  void skipLoopsReceivedTo(const std::string& peer, uint64_t count);

  // This station's run: a random epoch (drawEpoch) begun at start-up. Summaries numbered from
  // runStart() on are this run's; its loops are numbered from 0 per peer again.
  static constexpr size_t kMaxCounters = 64 * 65;  // Station's bound on senders x topics
  static uint64_t drawEpoch();
  void beginRun(uint64_t epoch);
  uint64_t epoch() const { return epoch_; }
  uint64_t runStart() const { return run_start_; }
  // A peer's summary of its run `epoch`, which began numbering at `start`. A new run: what was taken
  // of its summaries numbered from `start` on was an earlier run's (lost with it), so the count goes
  // back to `start` and they are taken again, this run's. kPast: a run it left (dropped).
  PeerRuns::Seen summaryRun(const std::string& peer, uint64_t epoch, uint64_t start);
  // A peer's loop of its run `epoch`: a new run numbers its loops from 0 again.
  PeerRuns::Seen loopRun(const std::string& peer, uint64_t epoch);
  PeerRuns summaryRuns(const std::string& peer) const;
  uint64_t loopEpoch(const std::string& peer) const;  // 0 when none heard

  // Loops held (published here, this station's or a peer's), by content: the last kMaxLoopsKept.
  static constexpr size_t kMaxLoopsKept = 100000;
  bool holdsLoop(const LoopKey& key) const { return loops_kept_.count(key) > 0; }
  // False, changing nothing, when held already.
  bool keepLoop(const LoopKey& key);
  // The deciders of the loops held for station's robot's keyframe `id` of `session`.
  std::vector<std::string> loopedBy(const std::string& station, const std::string& robot, uint32_t session,
                                    uint64_t id) const;

  // Per robot: the keyframe id below which this station's runs may have given ids out. A run
  // reserves ids in blocks, saved before it gives them (Station), so that a restart after a crash
  // (its map saved earlier, or not at all) gives out none of them again: 0 when none was reserved.
  uint64_t idFloor(size_t robot) const { return robot < id_floors_.size() ? id_floors_[robot] : 0; }
  void setIdFloor(size_t robot, uint64_t floor);

  // With a team key: the last message counter taken per sender and topic ("<sender> <topic>"), so
  // that a message recorded before a restart and replayed after it is refused.
  const std::map<std::string, uint64_t>& counters() const { return counters_; }
  void setCounters(std::map<std::string, uint64_t> counters) { counters_ = std::move(counters); }

  // The ledger as text (JSON), and back. fromText throws InvalidInput for text that is not a
  // ledger of this station with this many robots, changing nothing.
  std::string toText() const;
  void fromText(const std::string& text);

 private:
  struct Numbered {
    KeyframeIndex map_index = 0;
    uint64_t seq = 0;
  };
  uint64_t knownOf(uint64_t seq, const std::string& peer) const;

  std::string station_;
  size_t robots_ = 0;
  std::vector<uint64_t> id_floors_;  // per robot (idFloor)
  std::map<std::string, uint64_t> counters_;
  std::vector<Own> own_;                                         // by seq
  std::vector<std::vector<Numbered>> numbered_;                  // per robot, by map index: its keyframes' seqs
  std::map<std::string, uint64_t> received_;                     // per peer
  std::map<std::string, uint64_t> loops_sent_;                   // per peer
  std::map<std::string, uint64_t> loops_received_;               // per peer
  using KeyframeKeys = std::set<std::pair<uint32_t, uint64_t>>;  // (session, id)
  std::map<std::string, std::map<std::string, KeyframeKeys>> announced_;  // per peer, per robot of it
  uint64_t epoch_ = 0;
  uint64_t run_start_ = 0;
  std::map<std::string, PeerRuns> summary_runs_, loop_runs_;  // per peer
  std::set<LoopKey> loops_kept_;
  std::deque<LoopKey> loops_order_;  // loops_kept_ as kept, oldest first
};

// The ledger's file beside the maps (<folder>/<station>.team_ledger.json), read and written as the
// maps are: a link, a FIFO or a device at its name is refused (never followed, never waited on).
// readLedgerFile: its text, or none when the folder or the file is missing. writeLedgerFile:
// through a temporary file of its own, flushed to disk and renamed over it, so that a crash leaves
// the previous ledger whole. Both throw InvalidInput for what is not a regular file, and IoError
// (or std::filesystem's errors) when the folder or the file cannot be read or written.
std::optional<std::string> readLedgerFile(const std::string& path);
void writeLedgerFile(const std::string& path, const std::string& text);

}  // namespace mild
