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
// It is saved beside the maps so that a restarted station neither re-sends nor re-asks.

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "mild_lcd/common/types.hpp"
#include "mild_lcd/team/place_summary.hpp"

namespace mild {

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
  // Numbers up to `count` taken without a keyframe (peers hold summaries of a crashed run's
  // keyframes under them): their summaries carry nothing.
  void skipTo(uint64_t count);
  static constexpr uint64_t kNoKeyframe = ~uint64_t{0};  // Own::id of a skipped number
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
  // Numbers below `count` taken (a peer holds loops of a crashed run under them).
  void skipLoopsTo(const std::string& peer, uint64_t count);
  // Loops a peer decided for this station's keyframes: taken contiguously, as summaries.
  uint64_t loopsReceivedFrom(const std::string& peer) const;
  void tookLoop(const std::string& peer);
  // Counts peer's loops below `count` as taken (the decider can no longer send them: lost), at once.
  void skipLoopsReceivedTo(const std::string& peer, uint64_t count);

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
  std::vector<Own> own_;                                         // by seq
  std::vector<std::vector<Numbered>> numbered_;                  // per robot, by map index: its keyframes' seqs
  std::map<std::string, uint64_t> received_;                     // per peer
  std::map<std::string, uint64_t> loops_sent_;                   // per peer
  std::map<std::string, uint64_t> loops_received_;               // per peer
  using KeyframeKeys = std::set<std::pair<uint32_t, uint64_t>>;  // (session, id)
  std::map<std::string, std::map<std::string, KeyframeKeys>> announced_;  // per peer, per robot of it
};

}  // namespace mild
