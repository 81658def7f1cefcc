// A team across hosts in the core (team/station_ledger.hpp, team/place_summary.hpp,
// RobotTeam::askRemote / judgeRemote): which station decides a pair of keyframes, the ledger saved
// and read back, and two stations finding the loops between their robots from summaries as one
// node serving both robots does.

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>

#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <map>
#include <memory>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "../common/run_command.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/feature_front_end.hpp"
#include "mild_lcd/detector/robot_team.hpp"
#include "mild_lcd/io/database_directory.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "mild_lcd/team/place_summary.hpp"
#include "mild_lcd/team/station_identity.hpp"
#include "mild_lcd/team/station_ledger.hpp"
#include "mild_lcd/team/team_key.hpp"
#include "sample_halves.hpp"
#include "test_images.hpp"

namespace mild {
namespace {

// --- who decides ---

// Stations storing keyframes and taking each other's summaries in a random order, links going
// down and up. A station takes a peer's summaries in their order only, as the link does. Each
// time one takes a summary, the keyframes of its own map that StationLedger::eligiblePrefix
// returns are the pairs it decides.
struct SimulatedStation {
  explicit SimulatedStation(const std::string& name) : ledger(name, 1) {}
  StationLedger ledger;
  std::vector<PlaceSummary> summaries;  // its own, by number
};

PlaceSummary summaryOf(const SimulatedStation& s, uint64_t seq) {
  PlaceSummary summary;
  summary.station = s.ledger.station();
  summary.seq = seq;
  summary.known = s.ledger.own(seq).known;
  return summary;
}

TEST(StationLedger, EveryPairOfKeyframesOfTwoStationsIsDecidedExactlyOnce) {
  for (unsigned seed = 1; seed <= 20; ++seed) {
    std::mt19937 random(seed);
    std::vector<SimulatedStation> stations;
    for (const char* name : {"charlie", "alpha", "bravo"}) stations.emplace_back(name);
    const size_t n = stations.size();
    std::vector<std::vector<bool>> link_up(n, std::vector<bool>(n, true));
    // decided[(station a, seq a, station b, seq b)] with a < b: how many times.
    std::map<std::tuple<size_t, uint64_t, size_t, uint64_t>, int> decided;
    for (int step = 0; step < 600; ++step) {
      const size_t s = random() % n;
      const int action = static_cast<int>(random() % 10);
      if (action < 3) {
        stations[s].ledger.recordOwn(0, stations[s].ledger.ownCount(),
                                     static_cast<KeyframeIndex>(stations[s].ledger.ownCount()));
      } else if (action == 3) {
        const size_t t = random() % n;
        if (t != s) link_up[s][t] = link_up[t][s] = !link_up[s][t];  // an outage starts or ends
      } else {
        const size_t from = random() % n;
        if (from == s || !link_up[s][from]) continue;
        SimulatedStation& me = stations[s];
        const SimulatedStation& peer = stations[from];
        const std::string& peer_name = peer.ledger.station();
        const uint64_t next = me.ledger.received(peer_name);
        if (next >= peer.ledger.ownCount()) continue;
        const PlaceSummary summary = summaryOf(peer, next);
        const KeyframeIndex mine = static_cast<KeyframeIndex>(me.ledger.ownCount());
        const KeyframeIndex prefix = me.ledger.eligiblePrefix(0, mine, summary);
        for (KeyframeIndex j = 0; j < prefix; ++j) {
          const auto key =
              s < from ? std::make_tuple(s, uint64_t{j}, from, next) : std::make_tuple(from, next, s, uint64_t{j});
          ++decided[key];
        }
        me.ledger.took(peer_name);
      }
    }
    // Every link up, every summary taken: then every pair has been looked at.
    bool progress = true;
    while (progress) {
      progress = false;
      for (size_t s = 0; s < n; ++s) {
        for (size_t from = 0; from < n; ++from) {
          if (from == s) continue;
          SimulatedStation& me = stations[s];
          const std::string& peer_name = stations[from].ledger.station();
          const uint64_t next = me.ledger.received(peer_name);
          if (next >= stations[from].ledger.ownCount()) continue;
          const PlaceSummary summary = summaryOf(stations[from], next);
          const KeyframeIndex prefix =
              me.ledger.eligiblePrefix(0, static_cast<KeyframeIndex>(me.ledger.ownCount()), summary);
          for (KeyframeIndex j = 0; j < prefix; ++j) {
            const auto key =
                s < from ? std::make_tuple(s, uint64_t{j}, from, next) : std::make_tuple(from, next, s, uint64_t{j});
            ++decided[key];
          }
          me.ledger.took(peer_name);
          progress = true;
        }
      }
    }
    size_t pairs = 0;
    for (size_t a = 0; a < n; ++a) {
      for (size_t b = a + 1; b < n; ++b) {
        for (uint64_t i = 0; i < stations[a].ledger.ownCount(); ++i) {
          for (uint64_t j = 0; j < stations[b].ledger.ownCount(); ++j) {
            const auto it = decided.find({a, i, b, j});
            ASSERT_TRUE(it != decided.end() && it->second == 1)
                << "seed " << seed << ": keyframe " << i << " of " << stations[a].ledger.station() << " and " << j
                << " of " << stations[b].ledger.station() << " decided " << (it == decided.end() ? 0 : it->second)
                << " times";
            ++pairs;
          }
        }
      }
    }
    EXPECT_GT(pairs, 1000u);
  }
}

TEST(StationLedger, KeyframesStoredBeforeTheLedgerOrAMapReplacementAreEveryonesToAsk) {
  StationLedger ledger("alpha", 2);
  ledger.recordOwn(1, 7, 5);  // robot 1's map held 5 keyframes (a loaded map) before this one
  PlaceSummary s;
  s.station = "bravo";
  s.seq = 0;
  s.known = {{"alpha", 1}};  // bravo held our summary 0 when it stored this
  EXPECT_EQ(ledger.eligiblePrefix(1, 6, s), 6u);
  s.known = {};                                   // it did not: the pair is concurrent,
  EXPECT_EQ(ledger.eligiblePrefix(1, 6, s), 6u);  // alpha sorts first and decides
  s.station = "aaron";                            // a station sorting before alpha decides it
  EXPECT_EQ(ledger.eligiblePrefix(1, 6, s), 5u);
  ledger.forgetBeyond(1, 5);  // a map saved before keyframe 5 was stored: it is not numbered any more
  EXPECT_EQ(ledger.eligiblePrefix(1, 6, s), 6u);
  ledger.recordOwn(1, 8, 5);
  EXPECT_EQ(ledger.eligiblePrefix(1, 6, s), 5u);
  ledger.mapReplaced(1);
  EXPECT_EQ(ledger.eligiblePrefix(1, 6, s), 6u);
  EXPECT_EQ(ledger.eligiblePrefix(0, 3, s), 3u);  // robot 0 numbered nothing
}

TEST(StationLedger, IsSavedAndReadBackAndRefusesAnotherStationsChangingNothing) {
  StationLedger ledger("alpha", 2);
  ledger.took("bravo");
  ledger.took("bravo");
  ledger.recordOwn(0, 11, 0);
  ledger.recordOwn(1, 12, 0, {"charlie"});  // charlie could not be heard from then
  ledger.nextLoopFor("bravo");
  ledger.tookLoop("charlie");
  ledger.setIdFloor(1, 20000);
  ledger.setCounters({{"bravo /mild_team/status", 1796661181187402269u}});
  const std::string text = ledger.toText();

  StationLedger again("alpha", 2);
  again.fromText(text);
  EXPECT_EQ(again.toText(), text);
  EXPECT_EQ(again.ownCount(), 2u);
  EXPECT_EQ(again.received("bravo"), 2u);
  EXPECT_EQ(again.loopsSentTo("bravo"), 1u);
  EXPECT_EQ(again.loopsReceivedFrom("charlie"), 1u);
  EXPECT_EQ(again.own(1).known, (std::vector<std::pair<std::string, uint64_t>>{{"bravo", 2}}));
  EXPECT_EQ(again.own(1).unreachable, std::vector<std::string>{"charlie"});
  EXPECT_EQ(again.idFloor(0), 0u);  // none reserved
  EXPECT_EQ(again.idFloor(1), 20000u);
  EXPECT_EQ(again.counters().at("bravo /mild_team/status"), 1796661181187402269u);
  EXPECT_THROW(again.setIdFloor(2, 1), InvalidInput);
  EXPECT_EQ(again.recordOwn(0, 13, 1), 2u);  // numbering goes on from the saved count

  StationLedger other("bravo", 2);
  EXPECT_THROW(other.fromText(text), InvalidInput);
  StationLedger fewer("alpha", 1);
  EXPECT_THROW(fewer.fromText(text), InvalidInput);
  for (const std::string& bad :
       std::vector<std::string>{"", "{", "[]", "{\"format\": 3}", text.substr(0, text.size() / 2)}) {
    StationLedger kept("alpha", 2);
    kept.took("zulu");
    const std::string before = kept.toText();
    EXPECT_THROW(kept.fromText(bad), InvalidInput) << bad;
    EXPECT_EQ(kept.toText(), before);
  }
  EXPECT_THROW(StationLedger("Alpha", 1), InvalidInput);
  EXPECT_THROW(StationLedger("", 1), InvalidInput);
  EXPECT_THROW(StationLedger("alpha/x", 1), InvalidInput);
  EXPECT_THROW(StationLedger("alpha", 0), InvalidInput);
}

// The ledger's file is read and written as the maps are: whole (a crash leaves the previous one),
// none before the first save or without its folder, and a link or a FIFO planted at its name is
// refused at once, neither followed nor waited on (test_team_hostile plants them at a running node).
TEST(StationLedger, ItsFileIsWrittenWholeAndNeverThroughALinkOrAFifo) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("mild_ledger_file_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string path = (dir / ("alpha" + std::string(kTeamLedgerSuffix))).string();
  EXPECT_FALSE(readLedgerFile(path).has_value()) << "none saved yet";
  EXPECT_FALSE(readLedgerFile((dir / "absent" / "alpha.team_ledger.json").string()).has_value());
  StationLedger ledger("alpha", 1);
  ledger.took("bravo");
  writeLedgerFile(path, ledger.toText());
  ledger.took("bravo");
  writeLedgerFile(path, ledger.toText());
  EXPECT_EQ(readLedgerFile(path), ledger.toText());
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), std::filesystem::directory_iterator()), 1)
      << "no temporary file left beside it";
  const std::string outside = (dir / "outside.txt").string();
  std::ofstream(outside) << "kept";
  std::filesystem::remove(path);
  std::filesystem::create_symlink(outside, path);
  EXPECT_THROW(readLedgerFile(path), InvalidInput);
  EXPECT_THROW(writeLedgerFile(path, ledger.toText()), InvalidInput);
  std::ifstream kept(outside);
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(kept), {}), "kept") << "written through the link";
  std::filesystem::remove(path);
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  EXPECT_THROW(readLedgerFile(path), InvalidInput) << "a FIFO is refused, not waited on";
  EXPECT_THROW(writeLedgerFile(path, ledger.toText()), InvalidInput);
  std::filesystem::remove_all(dir);
}

// A remote robot's filters into this team's maps are the team's to keep consistent: a map
// replaced (RobotTeam::mapChanged) or all reset starts them over, as it does the robots' own pairs.
// A decider that can no longer send some loops (it restarted): they are counted taken at once,
// whatever their number (one step each once stalled a station for a peer's false 2^62), never back.
TEST(StationLedger, LoopsADeciderCanNoLongerSendAreSkippedAtOnce) {
  StationLedger ledger("alpha", 1);
  ledger.tookLoop("bravo");
  ledger.skipLoopsReceivedTo("bravo", uint64_t{1} << 62);
  EXPECT_EQ(ledger.loopsReceivedFrom("bravo"), uint64_t{1} << 62);
  ledger.skipLoopsReceivedTo("bravo", 5);
  EXPECT_EQ(ledger.loopsReceivedFrom("bravo"), uint64_t{1} << 62) << "never back";
  EXPECT_EQ(ledger.loopsReceivedFrom("charlie"), 0u);
}

// The keyframes a peer announced are the only ones its loops may name as candidates, across a
// restart too (a loop resent after it names a keyframe announced before): kept in the ledger, by
// robot, session and id (ids repeat across sessions). A ledger written before they were kept reads
// as one that knows of none.
TEST(StationLedger, KeepsWhatEachPeerAnnouncedAcrossARestart) {
  StationLedger ledger("alpha", 1);
  ledger.announced("bravo", "b1", 0, 45);
  ledger.announced("bravo", "b2", 1, 45);
  StationLedger again("alpha", 1);
  again.fromText(ledger.toText());
  EXPECT_TRUE(again.wasAnnounced("bravo", "b1", 0, 45));
  EXPECT_TRUE(again.wasAnnounced("bravo", "b2", 1, 45));
  EXPECT_FALSE(again.wasAnnounced("bravo", "b1", 1, 45)) << "another session's keyframe 45";
  EXPECT_FALSE(again.wasAnnounced("bravo", "b2", 0, 45));
  EXPECT_FALSE(again.wasAnnounced("charlie", "b1", 0, 45)) << "another station's robot of that name";
  EXPECT_FALSE(again.wasAnnounced("bravo", "b1", 0, 46));

  nlohmann::json older = nlohmann::json::parse(ledger.toText());
  older.erase("announced");
  StationLedger from_older("alpha", 1);
  from_older.fromText(older.dump());
  EXPECT_FALSE(from_older.wasAnnounced("bravo", "b1", 0, 45));
}

// A station's runs: a peer keys what it took of a station by its run's epoch, so that a run after
// a crash, numbering from the last saved ledger, is never taken for copies of the crashed run's;
// a run it left is dropped. Each run numbers its loops from 0, and a peer counts them per run.
TEST(StationLedger, APeerKeysWhatItTookByTheStationsRun) {
  StationLedger alpha("alpha", 1);
  EXPECT_EQ(alpha.summaryRun("charlie", 7, 0), PeerRuns::Seen::kNew);
  for (int i = 0; i < 100; ++i) alpha.took("charlie");
  EXPECT_EQ(alpha.summaryRun("charlie", 7, 0), PeerRuns::Seen::kCurrent);
  // charlie crashed with 40 of its summaries in its saved ledger: its run 8 numbers from 40.
  EXPECT_EQ(alpha.summaryRun("charlie", 8, 40), PeerRuns::Seen::kNew);
  EXPECT_EQ(alpha.received("charlie"), 40u) << "the crashed run's 40 .. 99 are not this run's";
  EXPECT_EQ(alpha.summaryRun("charlie", 7, 0), PeerRuns::Seen::kPast);
  EXPECT_EQ(alpha.received("charlie"), 40u);
  // A restart of a station behind: nothing it took goes back further than needed.
  EXPECT_EQ(alpha.summaryRun("charlie", 9, 1000), PeerRuns::Seen::kNew);
  EXPECT_EQ(alpha.received("charlie"), 40u);

  alpha.tookLoop("charlie");
  EXPECT_EQ(alpha.loopRun("charlie", 8), PeerRuns::Seen::kNew);
  EXPECT_EQ(alpha.loopsReceivedFrom("charlie"), 0u);
  alpha.tookLoop("charlie");
  EXPECT_EQ(alpha.loopRun("charlie", 8), PeerRuns::Seen::kCurrent);
  EXPECT_EQ(alpha.loopsReceivedFrom("charlie"), 1u);
  EXPECT_EQ(alpha.loopEpoch("charlie"), 8u);

  StationLedger again("alpha", 1);
  again.fromText(alpha.toText());
  EXPECT_EQ(again.toText(), alpha.toText());
  EXPECT_EQ(again.summaryRun("charlie", 7, 0), PeerRuns::Seen::kPast) << "runs left are kept across a restart";
  again.nextLoopFor("charlie");
  const uint64_t epoch = StationLedger::drawEpoch();
  EXPECT_NE(epoch, 0u);
  again.beginRun(epoch);
  EXPECT_EQ(again.epoch(), epoch);
  EXPECT_EQ(again.loopsSentTo("charlie"), 0u) << "each run numbers its loops from 0";
  EXPECT_NE(StationLedger::drawEpoch(), epoch);

  PeerRuns runs;
  for (uint64_t e = 1; e <= 100; ++e) EXPECT_EQ(runs.see(e), PeerRuns::Seen::kNew);
  EXPECT_EQ(runs.past.size(), PeerRuns::kMaxPast);
}

// Loops are held by content, saved, bounded; a keyframe's summary names the deciders of the loops
// held for it.
TEST(StationLedger, HoldsLoopsByTheirContent) {
  StationLedger charlie("charlie", 1);
  const LoopKey key{"charlie", "robot5", 1, 45, "alpha"};
  EXPECT_TRUE(charlie.keepLoop(key));
  EXPECT_FALSE(charlie.keepLoop(key)) << "a copy";
  EXPECT_TRUE(charlie.keepLoop({"charlie", "robot5", 1, 45, "bravo"}));
  EXPECT_TRUE(charlie.keepLoop({"charlie", "robot5", 0, 45, "alpha"}));
  EXPECT_EQ(charlie.loopedBy("charlie", "robot5", 1, 45), (std::vector<std::string>{"alpha", "bravo"}));
  EXPECT_TRUE(charlie.loopedBy("charlie", "robot5", 2, 45).empty()) << "another session's keyframe 45";
  StationLedger again("charlie", 1);
  again.fromText(charlie.toText());
  EXPECT_TRUE(again.holdsLoop(key));
  EXPECT_FALSE(again.holdsLoop({"charlie", "robot6", 1, 45, "alpha"}));
  for (uint64_t id = 0; id < StationLedger::kMaxLoopsKept; ++id) again.keepLoop({"charlie", "robot6", 0, id, "x"});
  EXPECT_FALSE(again.holdsLoop(key)) << "the oldest go beyond the bound";
  EXPECT_TRUE(again.holdsLoop({"charlie", "robot6", 0, 0, "x"}));

  nlohmann::json older = nlohmann::json::parse(charlie.toText());
  older.erase("loops_kept");
  older.erase("summary_runs");
  older.erase("loop_runs");
  older.erase("epoch");
  StationLedger from_older("charlie", 1);
  from_older.fromText(older.dump());
  EXPECT_FALSE(from_older.holdsLoop(key));
}

// Two stations as the link runs them (summaries taken in order by (station, run, number), loops
// numbered per run, held by content, the ledger written at an autosave, and after each loop or
// not), alpha killed at every point of the run and restarted on its last saved ledger, its first
// 20 summaries after: every one is taken by charlie, no loop is published twice on either side,
// and each names the keyframe it was decided on. Without the ledger written after each loop, what
// keeps alpha from deciding again is charlie's summaries naming it (looped_by).
TEST(StationLedger, ARestartAfterAKillAtAnyPointNeitherLosesNorRepeats) {
  constexpr uint64_t kCharlie = 100, kAlphaBefore = 30, kAlphaAfter = 20;
  const auto decides = [](uint64_t id) { return id % 5 != 1; };  // alpha finds a loop for most
  for (uint64_t kill = 0; kill <= kCharlie + kAlphaBefore; ++kill) {
    for (const std::pair<uint64_t, bool>& variant : std::vector<std::pair<uint64_t, bool>>{
             {0, true}, {kill / 2, true}, {kill, true}, {0, false}, {kill / 2, false}}) {
      const uint64_t autosave = variant.first;
      const bool write_through = variant.second;
      StationLedger charlie("charlie", 1);
      auto alpha = std::make_unique<StationLedger>("alpha", 1);
      const uint64_t charlie_epoch = 11;
      charlie.beginRun(charlie_epoch);
      uint64_t alpha_epoch = 21;
      alpha->beginRun(alpha_epoch);
      std::string saved;  // alpha's ledger as last written
      std::map<LoopKey, int> published_alpha, published_charlie;
      uint64_t charlie_took_after = 0;
      // charlie's summary `seq` (robot5's keyframe seq of session 0), with the deciders of the
      // loops charlie holds for it, taken by alpha in order.
      const auto alphaTakes = [&](uint64_t seq) {
        if (alpha->summaryRun("charlie", charlie_epoch, 0) == PeerRuns::Seen::kPast) return;
        if (seq != alpha->received("charlie")) return;
        alpha->took("charlie");
        const LoopKey key{"charlie", "robot5", 0, seq, "alpha"};
        const std::vector<std::string> by = charlie.loopedBy("charlie", "robot5", 0, seq);
        if (std::find(by.begin(), by.end(), "alpha") != by.end() || alpha->holdsLoop(key) || !decides(seq)) return;
        alpha->keepLoop(key);
        if (write_through) saved = alpha->toText();  // before it is published
        ++published_alpha[key];
        const uint64_t number = alpha->nextLoopFor("charlie");
        if (charlie.loopRun("alpha", alpha_epoch) == PeerRuns::Seen::kPast) return;
        if (number != charlie.loopsReceivedFrom("alpha")) return;
        charlie.tookLoop("alpha");
        if (charlie.keepLoop(key)) ++published_charlie[key];
      };
      const auto charlieTakes = [&](uint64_t seq, bool after) {
        if (charlie.summaryRun("alpha", alpha->epoch(), alpha->runStart()) == PeerRuns::Seen::kPast) return;
        if (seq < charlie.received("alpha")) return;  // a copy
        ASSERT_EQ(seq, charlie.received("alpha"));
        charlie.took("alpha");
        if (after) ++charlie_took_after;
      };
      uint64_t step = 0;
      for (uint64_t c = 0, a = 0; c < kCharlie || a < kAlphaBefore; ++step) {
        if (step == autosave) saved = alpha->toText();
        if (step == kill) break;
        if (a < kAlphaBefore && (c >= kCharlie || step % 4 == 0)) {
          charlieTakes(alpha->recordOwn(0, a, static_cast<KeyframeIndex>(a)), false);
          ++a;
        } else {
          alphaTakes(c++);
        }
      }
      // SIGKILL: alpha restarts on its folder, a new run.
      alpha = std::make_unique<StationLedger>("alpha", 1);
      if (!saved.empty()) alpha->fromText(saved);
      alpha->forgetBeyond(0, 0);
      alpha_epoch = 22;
      alpha->beginRun(alpha_epoch);
      // It asks charlie for what it misses (charlie's summaries carry the deciders of its loops).
      for (uint64_t c = alpha->received("charlie"); c < kCharlie; ++c) alphaTakes(c);
      for (uint64_t a = 0; a < kAlphaAfter; ++a) {
        charlieTakes(alpha->recordOwn(0, 1000 + a, static_cast<KeyframeIndex>(a)), true);
      }
      const std::string at = "killed at " + std::to_string(kill) + ", saved at " + std::to_string(autosave) +
                             (write_through ? " and after each loop" : "");
      EXPECT_EQ(charlie_took_after, kAlphaAfter) << at;
      for (uint64_t c = 0; c < kCharlie; ++c) {
        const LoopKey key{"charlie", "robot5", 0, c, "alpha"};
        const int expected = decides(c) ? 1 : 0;
        EXPECT_EQ(published_alpha[key], expected) << "alpha, keyframe " << c << ", " << at;
        EXPECT_EQ(published_charlie[key], expected) << "charlie, keyframe " << c << ", " << at;
      }
      EXPECT_EQ(published_alpha.size(), published_charlie.size());
    }
  }
}

// The team key's MAC is HMAC-SHA256 (RFC 4231, test case 6: a key longer than SHA-256's block), and
// a single changed bit of the message or of the MAC fails it.
TEST(TeamKey, IsHmacSha256AndRefusesAnyChange) {
  const TeamKey key(std::string(131, '\xaa'));
  const std::string data = "Test Using Larger Than Block-Size Key - Hash Key First";
  const auto* bytes = reinterpret_cast<const uint8_t*>(data.data());
  const TeamKey::Mac mac = key.mac(bytes, data.size());
  std::string hex;
  for (uint8_t b : mac) {
    static const char* digits = "0123456789abcdef";
    hex += digits[b >> 4];
    hex += digits[b & 15];
  }
  EXPECT_EQ(hex, "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54");
  EXPECT_TRUE(key.verify(bytes, data.size(), mac.data(), mac.size()));
  std::string changed = data;
  changed[3] ^= 1;
  EXPECT_FALSE(key.verify(reinterpret_cast<const uint8_t*>(changed.data()), changed.size(), mac.data(), mac.size()));
  TeamKey::Mac wrong = mac;
  wrong[31] ^= 1;
  EXPECT_FALSE(key.verify(bytes, data.size(), wrong.data(), wrong.size()));
  EXPECT_FALSE(key.verify(bytes, data.size(), mac.data(), 16)) << "a truncated MAC";
  EXPECT_FALSE(TeamKey(std::string(32, 'b')).verify(bytes, data.size(), mac.data(), mac.size())) << "another key";
  EXPECT_THROW(TeamKey("short"), InvalidInput);
}

// The key file must be readable only by its owner, this process's user, and a regular file: a key
// others can read is no key (refused, saying why), a link or FIFO is never followed or waited on.
TEST(TeamKey, IsReadOnlyFromAFileOnlyItsOwnerCanRead) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("mild_team_key_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string file = (dir / "team.key").string();
  std::ofstream(file) << std::string(64, 'f') << "\n";
  ::chmod(file.c_str(), 0644);
  EXPECT_THROW(TeamKey::fromFile(file), InvalidInput) << "readable by others";
  ::chmod(file.c_str(), 0640);
  EXPECT_THROW(TeamKey::fromFile(file), InvalidInput) << "readable by its group";
  ::chmod(file.c_str(), 0600);
  const TeamKey key = TeamKey::fromFile(file);
  const std::string data = "x";
  const auto* bytes = reinterpret_cast<const uint8_t*>(data.data());
  const TeamKey::Mac mac = key.mac(bytes, 1);
  EXPECT_TRUE(TeamKey(std::string(64, 'f')).verify(bytes, 1, mac.data(), mac.size()))
      << "the trailing newline is not key";
  if (::geteuid() == 0) {
    ASSERT_EQ(::chown(file.c_str(), 65534, 65534), 0);
    EXPECT_THROW(TeamKey::fromFile(file), InvalidInput) << "owned by another user";
    ASSERT_EQ(::chown(file.c_str(), 0, 0), 0);
  }
  std::filesystem::create_symlink(file, dir / "link.key");
  EXPECT_THROW(TeamKey::fromFile((dir / "link.key").string()), InvalidInput);
  ASSERT_EQ(::mkfifo((dir / "fifo.key").c_str(), 0600), 0);
  EXPECT_THROW(TeamKey::fromFile((dir / "fifo.key").string()), InvalidInput);
  std::ofstream((dir / "short.key").string()) << "0123456789";
  ::chmod((dir / "short.key").c_str(), 0600);
  EXPECT_THROW(TeamKey::fromFile((dir / "short.key").string()), InvalidInput);
  EXPECT_THROW(TeamKey::fromFile((dir / "absent.key").string()), IoError);
  std::filesystem::remove_all(dir);
}

// A station's name is bound to its own key: a message sealed by alpha verifies as alpha's only,
// and only whole; a key that is not the roster's for the station's name, a station key without a
// roster, and a roster that is not a folder of regular "<station>.pub" files are refused.
TEST(StationIdentity, ANameIsAcceptedOnlyWithItsOwnKey) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("mild_station_keys_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "roster");
  for (const std::string name : {"alpha", "bravo"}) {
    const std::string key = (dir / (name + ".pem")).string();
    const test::CommandResult made =
        test::runCommand("(umask 077; openssl genpkey -algorithm ed25519 -out " + key + ") && openssl pkey -in " + key +
                         " -pubout -out " + (dir / "roster" / (name + ".pub")).string());
    ASSERT_EQ(made.status, 0) << made.output;
  }
  const std::string roster = (dir / "roster").string();
  std::ofstream((dir / "team.key").string()) << std::string(64, 'f');
  ::chmod((dir / "team.key").c_str(), 0600);
  const TeamCredentials alpha =
      TeamCredentials::fromFiles((dir / "team.key").string(), (dir / "alpha.pem").string(), roster, "alpha");
  const TeamCredentials bravo =
      TeamCredentials::fromFiles((dir / "team.key").string(), (dir / "bravo.pem").string(), roster, "bravo");
  ASSERT_NE(alpha.roster(), nullptr);
  EXPECT_EQ(alpha.roster()->size(), 2u);
  const std::string data = "a summary";
  const auto* bytes = reinterpret_cast<const uint8_t*>(data.data());
  const std::vector<uint8_t> seal = alpha.seal(bytes, data.size());
  EXPECT_EQ(seal.size(), TeamKey::kMacBytes + StationSigner::kSignatureBytes);
  EXPECT_TRUE(bravo.verify("alpha", bytes, data.size(), seal));
  EXPECT_FALSE(bravo.verify("bravo", bytes, data.size(), seal)) << "alpha's seal in bravo's name";
  EXPECT_FALSE(bravo.verify("zulu", bytes, data.size(), seal)) << "a name not in the roster";
  std::vector<uint8_t> changed = seal;
  changed.back() ^= 1;
  EXPECT_FALSE(bravo.verify("alpha", bytes, data.size(), changed)) << "a changed signature";
  changed = seal;
  changed.front() ^= 1;
  EXPECT_FALSE(bravo.verify("alpha", bytes, data.size(), changed)) << "a changed team MAC";
  EXPECT_FALSE(bravo.verify("alpha", bytes, data.size() - 1, seal)) << "changed data";
  EXPECT_FALSE(bravo.verify("alpha", bytes, data.size(), std::vector<uint8_t>(seal.begin(), seal.begin() + 32)));
  // Membership alone (the team key, no roster) cannot pass for a named station, nor the reverse.
  const TeamCredentials member = TeamCredentials::fromFiles((dir / "team.key").string(), "", "", "alpha");
  EXPECT_FALSE(bravo.verify("alpha", bytes, data.size(), member.seal(bytes, data.size())));
  EXPECT_FALSE(member.verify("alpha", bytes, data.size(), seal));
  EXPECT_TRUE(member.verify("alpha", bytes, data.size(), member.seal(bytes, data.size())));

  EXPECT_THROW(TeamCredentials::fromFiles("", (dir / "bravo.pem").string(), roster, "alpha"), InvalidInput)
      << "bravo's key for alpha";
  EXPECT_THROW(TeamCredentials::fromFiles("", (dir / "alpha.pem").string(), roster, "charlie"), InvalidInput)
      << "a station not in the roster";
  EXPECT_THROW(TeamCredentials::fromFiles("", (dir / "alpha.pem").string(), "", "alpha"), InvalidInput);
  EXPECT_THROW(TeamCredentials::fromFiles("", "", roster, "alpha"), InvalidInput);
  ::chmod((dir / "alpha.pem").c_str(), 0644);
  EXPECT_THROW(TeamCredentials::fromFiles("", (dir / "alpha.pem").string(), roster, "alpha"), InvalidInput)
      << "a private key others can read";
  ::chmod((dir / "alpha.pem").c_str(), 0600);
  std::filesystem::create_symlink(dir / "roster" / "alpha.pub", dir / "roster" / "charlie.pub");
  EXPECT_THROW(StationRoster::fromFolder(roster), InvalidInput) << "a link in the roster";
  std::filesystem::remove(dir / "roster" / "charlie.pub");
  std::filesystem::copy_file(dir / "roster" / "alpha.pub", dir / "roster" / "Charlie.pub");
  EXPECT_THROW(StationRoster::fromFolder(roster), InvalidInput) << "not a station name";
  std::filesystem::remove(dir / "roster" / "Charlie.pub");
  std::ofstream((dir / "roster" / "charlie.pub").string()) << "not a key";
  EXPECT_THROW(StationRoster::fromFolder(roster), InvalidInput) << "not a public key";
  std::filesystem::remove(dir / "roster" / "charlie.pub");
  EXPECT_NO_THROW(StationRoster::fromFolder(roster));
  std::filesystem::create_directories(dir / "empty");
  EXPECT_THROW(StationRoster::fromFolder((dir / "empty").string()), InvalidInput);
  EXPECT_THROW(StationRoster::fromFolder((dir / "absent").string()), IoError);
  std::filesystem::remove_all(dir);
}

TEST(RobotTeamRemote, AMapChangedStartsTheRemoteRobotsFiltersOver) {
  const DetectorParams params;
  const FeatureFrontEnd front_end(params.features);
  std::vector<Features> features;
  for (int i = 0; i < 30; ++i) {
    features.push_back(
        front_end.extract(Observation::ofImage(test::sampleFrames()[i], PixelFormat::kGray, 0.1 * i)).features);
  }
  const auto answers = [&](int change_between) {
    RobotTeam team(params, {"a"});
    for (int i = 0; i < 20; ++i) team.process(Observation::ofFeatures(features[i], 0.1 * i, i, 0));
    std::vector<double> beliefs;
    for (int i = 20; i < 30; ++i) {
      if (change_between == 1 && i == 25) team.mapChanged(0);
      if (change_between == 2 && i == 25) team.remoteSessionBegan("far/r");  // its station restarted
      if (change_between == 3 && i == 25) team.remoteSessionBegan("other/r");
      const RobotTeam::RemoteAnswer a = team.askRemote("far/r", features[i - 15].descriptors, 500, {kAllKeyframes});
      beliefs.push_back(a.candidates.empty() ? 0.0 : a.candidates.front().filter_probability);
    }
    EXPECT_EQ(team.remoteRobots(), 1u);
    return beliefs;
  };
  const std::vector<double> kept = answers(0);
  // Before the change the same; right after it the filter starts from "no loop" again.
  for (const int change : {1, 2}) {
    const std::vector<double> restarted = answers(change);
    for (int i = 0; i < 5; ++i) EXPECT_DOUBLE_EQ(kept[i], restarted[i]);
    EXPECT_NE(kept[5], restarted[5]) << change;
  }
  EXPECT_EQ(answers(3), kept) << "another remote robot's new session changes nothing here";
  RobotTeam team(params, {"a", "b"});
  EXPECT_THROW(team.askRemote("far/r", features[0].descriptors, 500, {kAllKeyframes}), InvalidInput);
}

// --- summaries ---

TEST(PlaceSummary, CarriesTheStrongestDescriptorsInTheKeyframesOrder) {
  Features f;
  for (int i = 0; i < 6; ++i) {
    cv::KeyPoint k(static_cast<float>(i), 0.f, 7.f);
    k.response = static_cast<float>((i * 7) % 6);  // 0 1 2 3 4 5 permuted: 0, 1, 2, 3, 4, 5 -> 0 1 2 3 4 5
    f.keypoints.push_back(k);
    Descriptor d;
    d.words[0] = static_cast<uint64_t>(i);
    f.descriptors.push_back(d);
  }
  f.keypoints[0].response = 10.f;
  f.keypoints[3].response = 9.f;
  f.keypoints[5].response = 8.f;
  const DescriptorList strongest = strongestDescriptors(f, 3);
  ASSERT_EQ(strongest.size(), 3u);
  EXPECT_EQ(strongest[0].words[0], 0u);
  EXPECT_EQ(strongest[1].words[0], 3u);
  EXPECT_EQ(strongest[2].words[0], 5u);
  EXPECT_EQ(strongestDescriptors(f, 100).size(), 6u);
  EXPECT_EQ(descriptorsWithin(kDefaultSummaryBytes, 32), 243u);
  EXPECT_EQ(descriptorsWithin(kDefaultSummaryBytes, 64), 121u);
  EXPECT_EQ(descriptorsWithin(10, 32), 1u);
}

// --- two stations on the sample ---

constexpr int kFrames = 300;
constexpr int kHalf = 150;

struct Decisions {
  std::set<int> found;  // queries (second half) with an accepted true loop into the first half
  size_t wrong = 0;     // accepted loops that are not true
  size_t pulls = 0;     // keyframes whose features were fetched
};

// Pairs of frames closer than this are neighbours on the path, not loops (evaluate()'s min_gap):
// the end of the first half and the start of the second are one place seen twice in a row.
constexpr int kMinGap = 40;

// The accepted candidates of a keyframe of either half into the other half's map, judged by the
// ground truth (which pairs the later frame with the earlier one).
void judgeAccepted(const GroundTruth& truth, int query, const std::vector<LoopCandidate>& candidates, Decisions& d) {
  for (const LoopCandidate& c : candidates) {
    const int other = static_cast<int>(c.id);
    if (!c.accepted || (query < kHalf) == (other < kHalf) || std::abs(query - other) < kMinGap) continue;
    const std::pair<int, int> pair{std::max(query, other), std::min(query, other)};
    if (truth.right.count(pair)) {
      if (query >= kHalf) d.found.insert(query);
    } else if (!truth.dont_care.count(pair)) {
      ++d.wrong;
    }
  }
}

// Station alpha's robot maps frames 0..149 while bravo's maps 150..299 (whose end comes back to
// alpha's start), one keyframe each in turn, each station taking the other's summary right after.
// Against one node serving both robots: every loop it accepts between them is accepted, and none it
// would call wrong. Also measures what smaller summaries keep (docs/multi_robot.md).
TEST(Stations, TwoStationsFindTheLoopsBetweenTheirRobotsAsOneNodeServingBothDoes) {
  const GroundTruth truth = test::sampleAcrossHalves();
  const DetectorParams params;
  const FeatureFrontEnd front_end(params.features);
  std::vector<Features> features;
  for (int i = 0; i < kFrames; ++i) {
    features.push_back(
        front_end.extract(Observation::ofImage(test::sampleFrames()[i], PixelFormat::kGray, 0.1 * i)).features);
  }

  Decisions single;
  {
    RobotTeam team(params, {"a", "b"});
    for (int k = 0; k < kHalf; ++k) {
      judgeAccepted(truth, k, team.process(Observation::ofFeatures(features[k], 0.1 * k, k, 0)).candidates, single);
      const int j = kHalf + k;
      const DetectionResult r = team.process(Observation::ofFeatures(features[j], 0.1 * j, j, 1));
      judgeAccepted(truth, j, r.candidates, single);
    }
  }
  ASSERT_GT(single.found.size(), 20u);
  EXPECT_EQ(single.wrong, 0u);

  for (const size_t summary_size : {size_t{50}, size_t{100}, size_t{243}, size_t{10000}}) {
    RobotTeam alpha_team(params, {"robot1"}), bravo_team(params, {"robot2"});
    StationLedger alpha("alpha", 1), bravo("bravo", 1);
    Decisions distributed;
    for (int k = 0; k < kHalf; ++k) {
      const int j = kHalf + k;
      const DetectionResult ra = alpha_team.process(Observation::ofFeatures(features[k], 0.1 * k, k, 0));
      PlaceSummary sa;
      sa.station = "alpha";
      sa.seq = alpha.recordOwn(0, ra.query_id, ra.query_index);
      sa.known = alpha.own(sa.seq).known;
      const DetectionResult rb = bravo_team.process(Observation::ofFeatures(features[j], 0.1 * j, j, 0));
      PlaceSummary sb;
      sb.station = "bravo";
      sb.seq = bravo.recordOwn(0, rb.query_id, rb.query_index);
      sb.known = bravo.own(sb.seq).known;
      // alpha takes bravo's keyframe j: the loops of the second half into the first.
      RobotTeam::RemoteAnswer answer = alpha_team.askRemote(
          "bravo/robot2", strongestDescriptors(features[j], summary_size), features[j].descriptors.size(),
          {alpha.eligiblePrefix(0, static_cast<KeyframeIndex>(alpha_team.robot(0).map().size()), sb)});
      alpha.took("bravo");
      distributed.pulls += answer.needs_features;
      const DetectionResult judged =
          alpha_team.judgeRemote(std::move(answer), answer.needs_features ? &features[j] : nullptr);
      judgeAccepted(truth, j, judged.candidates, distributed);
      // bravo takes alpha's keyframe k: the loops of the first half into the second (few).
      RobotTeam::RemoteAnswer back = bravo_team.askRemote(
          "alpha/robot1", strongestDescriptors(features[k], summary_size), features[k].descriptors.size(),
          {bravo.eligiblePrefix(0, static_cast<KeyframeIndex>(bravo_team.robot(0).map().size()), sa)});
      bravo.took("alpha");
      distributed.pulls += back.needs_features;
      const DetectionResult judged_back =
          bravo_team.judgeRemote(std::move(back), back.needs_features ? &features[k] : nullptr);
      judgeAccepted(truth, k, judged_back.candidates, distributed);
    }
    size_t kept = 0;
    for (int q : single.found) kept += distributed.found.count(q);
    const double share = static_cast<double>(kept) / static_cast<double>(single.found.size());
    std::cout << "summary of " << summary_size << " descriptors: " << distributed.found.size()
              << " loop queries found (" << kept << " of the single node's " << single.found.size() << ", " << share
              << "), wrong " << distributed.wrong << ", features pulled for " << distributed.pulls << " of " << kFrames
              << " keyframes\n";
    RecordProperty("kept_share_" + std::to_string(summary_size), std::to_string(share));
    if (summary_size == descriptorsWithin(kDefaultSummaryBytes, params.features.descriptorBytes())) {
      EXPECT_GE(share, 0.95);
      EXPECT_EQ(distributed.wrong, 0u);
      EXPECT_LT(distributed.pulls, static_cast<size_t>(kFrames) / 2);
    }
  }
}

}  // namespace
}  // namespace mild
