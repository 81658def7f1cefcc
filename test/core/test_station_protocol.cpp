// The station protocol of a team across hosts without ROS (team/station.hpp): two Stations on the
// embedded sample, joined by an in-memory network the test drives (links that drop, stations that
// crash and restart on their saved ledger, a station joining late), and a Station fed hostile
// messages. Station alpha's robot maps frames 0..149 and bravo's 150..299, whose end comes back to
// alpha's start (test_stations, sample_halves.hpp): the loops between them are bravo's keyframes
// found in alpha's map, decided by alpha.

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <any>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/feature_front_end.hpp"
#include "mild_lcd/detector/robot_team.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "mild_lcd/team/place_summary.hpp"
#include "mild_lcd/team/station.hpp"
#include "mild_lcd/team/station_ledger.hpp"
#include "mild_lcd/team/team_messages.hpp"
#include "sample_halves.hpp"
#include "test_images.hpp"

namespace mild {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int kFrames = test::kSampleFrames;
constexpr int kHalf = test::kSampleHalf;
// Pairs of frames closer than this are neighbours on the path, not loops (as test_stations).
constexpr int kMinGap = 40;

// The sample's features, extracted once for every test (the slow part).
const std::vector<Features>& sampleFeatures() {
  static const std::vector<Features> features = [] {
    const DetectorParams params;
    const FeatureFrontEnd front_end(params.features);
    std::vector<Features> f;
    for (int i = 0; i < kFrames; ++i) {
      f.push_back(
          front_end.extract(Observation::ofImage(test::sampleFrames()[i], PixelFormat::kGray, 0.1 * i)).features);
    }
    return f;
  }();
  return features;
}

const GroundTruth& truth() {
  static const GroundTruth t = test::sampleAcrossHalves();
  return t;
}

// Accepted candidates of `query` into the other half, judged by the ground truth: `found` gets the
// second half's queries with a true loop, `wrong` counts the accepted pairs that are not true.
void judgeAccepted(int query, const std::vector<LoopCandidate>& candidates, std::set<int>& found, size_t& wrong) {
  for (const LoopCandidate& c : candidates) {
    const int other = static_cast<int>(c.id);
    if (!c.accepted || (query < kHalf) == (other < kHalf) || std::abs(query - other) < kMinGap) continue;
    const std::pair<int, int> pair{std::max(query, other), std::min(query, other)};
    if (truth().right.count(pair)) {
      if (query >= kHalf) found.insert(query);
    } else if (!truth().dont_care.count(pair)) {
      ++wrong;
    }
  }
}

// What one node serving both robots finds between them (the reference of test_stations).
const std::set<int>& singleNodeFinds() {
  static const std::set<int> found = [] {
    const std::vector<Features>& features = sampleFeatures();
    RobotTeam team(DetectorParams{}, {"a", "b"});
    std::set<int> f;
    size_t wrong = 0;
    for (int k = 0; k < kHalf; ++k) {
      judgeAccepted(k, team.process(Observation::ofFeatures(features[k], 0.1 * k, k, 0)).candidates, f, wrong);
      const int j = kHalf + k;
      judgeAccepted(j, team.process(Observation::ofFeatures(features[j], 0.1 * j, j, 1)).candidates, f, wrong);
    }
    EXPECT_EQ(wrong, 0u) << "the single node's reference";
    return f;
  }();
  return found;
}

std::string keyText(const LoopKey& k) {
  std::ostringstream s;
  s << k.station << "/" << k.robot << " session " << k.session << " keyframe " << k.id << " decided by " << k.decider;
  return s.str();
}

// --- the harness: a station's maps, and a network of stations ---

class TestMaps : public StationMaps {
 public:
  explicit TestMaps(std::vector<std::string> robots) : team_(DetectorParams{}, std::move(robots)) {}
  std::unique_lock<std::mutex> lock() override { return std::unique_lock<std::mutex>(mutex_); }
  RobotTeam& team() override { return team_; }
  uint64_t replaced() const override { return replaced_; }

 private:
  std::mutex mutex_;
  RobotTeam team_;
  uint64_t replaced_ = 0;
};

// What the harness puts in a PeerLoop's `published`: the loop as the query's station would publish it.
struct PublishedLoop {
  LoopKey key;
  std::vector<uint64_t> accepted;  // the decider's accepted candidates' ids
};

bool endsWith(const std::string& s, const std::string& end) {
  return s.size() >= end.size() && s.compare(s.size() - end.size(), end.size(), end) == 0;
}

// A figure of report(), as a number (the test fails when it is missing).
uint64_t figure(Station& station, const std::string& key) {
  for (const auto& [k, v] : station.report().values) {
    if (k == key) return std::stoull(v);
  }
  ADD_FAILURE() << "no figure '" << key << "' in the report";
  return 0;
}

struct Node {
  std::string name;
  std::vector<std::string> robots;
  std::unique_ptr<TestMaps> maps;
  std::unique_ptr<Station> station;
  std::optional<std::string> saved;  // the ledger as last persisted
  uint64_t restarts = 0;
  // What this station published: its own decisions (Outbox::published) and peers' loops taken.
  std::map<LoopKey, int> published, taken;
  std::vector<DecidedLoop> decided;
};

// How a station dies in the middle of handling what work() returned (crash tests).
enum class Kill {
  kAfterHandling,  // everything of the call persisted, published and sent, then killed
  kBeforePersist,  // at a call that would persist: killed before anything of it is done
  kAfterPersist,   // at a call that would persist: the ledger written, then killed before publishing
};

const char* killName(Kill k) {
  switch (k) {
    case Kill::kAfterHandling:
      return "AfterHandling";
    case Kill::kBeforePersist:
      return "BeforePersist";
    case Kill::kAfterPersist:
      return "AfterPersist";
  }
  return "?";
}

class Network {
 public:
  Clock::time_point now = Clock::time_point{} + std::chrono::hours(1);
  std::vector<std::unique_ptr<Node>> nodes;
  std::mt19937 random{1};
  double drop = 0.0;                         // the share of messages lost at random
  std::set<std::pair<size_t, size_t>> down;  // links down (both directions), as (lower, higher) index
  uint64_t next_epoch = 1000;
  uint64_t messages = 0, dropped = 0;
  std::map<std::string, uint64_t> lost;  // messages lost, by kind

  // A planned crash: `victim` dies at its first work() at or after `at` rounds that `kill` can hit.
  struct CrashPlan {
    size_t victim = 0;
    uint64_t at = 0;
    Kill kill = Kill::kAfterHandling;
    bool done = false;
    std::vector<LoopKey> lost;    // what the dying call would have published (kAfterPersist)
    uint64_t unacknowledged = 0;  // the victim's loops not yet acknowledged when it died
  };
  std::optional<CrashPlan> crash;
  uint64_t rounds = 0;

  size_t add(const std::string& name, const std::string& robot) {
    auto node = std::make_unique<Node>();
    node->name = name;
    node->robots = {robot};
    node->maps = std::make_unique<TestMaps>(node->robots);
    nodes.push_back(std::move(node));
    return nodes.size() - 1;
  }

  StationSettings settingsOf(const Node& n) {
    StationSettings s;
    s.station = n.name;
    s.robots = n.robots;
    s.now = [this] { return now; };
    return s;
  }

  // Starts (or restarts) node i's station on its last saved ledger.
  void start(size_t i) {
    Node& n = *nodes[i];
    n.station = std::make_unique<Station>(settingsOf(n), *n.maps);
    n.station->start(n.saved, false, next_epoch++);
    n.saved = n.station->ledgerText();  // as the link does before the first keyframe (the ids reserved)
  }

  bool linkUp(size_t a, size_t b) const { return down.count({std::min(a, b), std::max(a, b)}) == 0; }

  // Whether a message from a to b arrives.
  bool delivers(size_t from, size_t to, const char* kind) {
    ++messages;
    if (!nodes[to]->station || !linkUp(from, to) ||
        (drop > 0.0 && std::uniform_real_distribution<double>(0.0, 1.0)(random) < drop)) {
      ++dropped;
      ++lost[kind];
      return false;
    }
    return true;
  }

  size_t indexOf(const std::string& name) const {
    for (size_t i = 0; i < nodes.size(); ++i) {
      if (nodes[i]->name == name) return i;
    }
    return nodes.size();
  }

  static uint64_t wireBytes(const PlaceSummary& s) {
    return 200 + s.descriptor_data.size() + 40 * (s.known.size() + s.unreachable.size() + s.looped_by.size());
  }

  // Node i stores `frame` of the sample (as keyframe id `frame`) and broadcasts its summary.
  void store(size_t i, int frame) {
    Node& n = *nodes[i];
    PlaceSummary summary;
    {
      const auto lock = n.maps->lock();
      const DetectionResult result =
          n.maps->team().process(Observation::ofFeatures(sampleFeatures()[frame], 0.1 * frame, frame, 0));
      summary = n.station->stored(result);
    }
    summary.wire_bytes = wireBytes(summary);
    n.station->sentSummary(summary.wire_bytes);
    for (size_t to = 0; to < nodes.size(); ++to) {
      if (to != i && delivers(i, to, "summary")) nodes[to]->station->receive(summary, false);
    }
  }

  // The link's conversion of a decided loop into what its query's station receives.
  PeerLoop peerLoopOf(const Node& decider, const DecidedLoop& d) const {
    PeerLoop l;
    l.decider = decider.name;
    l.epoch = d.epoch;
    l.seq = d.seq;
    l.query = LoopKey{d.peer, d.query_robot, d.query_session, d.query_id, decider.name};
    PublishedLoop published{l.query, {}};
    for (const LoopCandidate& c : d.result.candidates) {
      PeerLoop::Candidate k;  // as the decider's link sends it
      k.station = decider.name;
      k.robot = decider.robots.at(c.robot);
      k.session = c.session;
      k.id = c.id;
      k.probability = c.probability;
      k.verified = c.verification.verified;
      k.accepted = !c.accepted;  // the peer's word, never taken: the station decides it again
      l.candidates.push_back(k);
      if (c.accepted) published.accepted.push_back(c.id);
    }
    l.published = published;
    l.wire_bytes = 500 + 300 * l.candidates.size();
    return l;
  }

  // Handles what node i's work() returned, as the link does: the ledger saved, the loops published,
  // the messages sent. A planned crash may cut it short.
  void handle(size_t i, Outbox out) {
    Node& n = *nodes[i];
    const bool dies = crash && !crash->done && crash->victim == i && rounds >= crash->at &&
                      (crash->kill == Kill::kAfterHandling || out.persist);
    if (dies) {
      crash->done = true;
      crash->unacknowledged = unacknowledged(i);
    }
    if (dies && crash->kill == Kill::kBeforePersist) return restart(i);
    if (out.persist) n.saved = n.station->ledgerText();
    if (dies && crash->kill == Kill::kAfterPersist) {
      for (const DecidedLoop& d : out.published) crash->lost.push_back(peerLoopOf(n, d).query);
      for (const auto& [robot, l] : out.taken)
        crash->lost.push_back(std::any_cast<const PublishedLoop&>(l.published).key);
      return restart(i);
    }
    for (const DecidedLoop& d : out.published) {
      ++n.published[peerLoopOf(n, d).query];
      n.decided.push_back(d);
    }
    for (const auto& [robot, l] : out.taken) {
      const PublishedLoop& p = std::any_cast<const PublishedLoop&>(l.published);
      EXPECT_EQ(n.robots.at(robot), p.key.robot) << "a loop taken on another robot than its query's";
      std::vector<uint64_t> accepted;  // as decided here: the decider's own decisions, by the same rule
      for (const PeerLoop::Candidate& c : l.candidates) {
        if (c.accepted) accepted.push_back(c.id);
      }
      EXPECT_EQ(accepted, p.accepted) << "accepted decided here differs from the decider's";
      ++n.taken[p.key];
    }
    for (const DecidedLoop& d : out.loops) {
      const size_t to = indexOf(d.peer);
      ASSERT_LT(to, nodes.size()) << "a loop for a station never heard of: " << d.peer;
      if (delivers(i, to, "loop")) nodes[to]->station->receive(peerLoopOf(n, d));
    }
    for (auto& [peer, request] : out.requests) {
      const size_t to = indexOf(peer);
      ASSERT_LT(to, nodes.size());
      if (delivers(i, to, "request")) nodes[to]->station->receive(request);
    }
    for (auto& [peer, summary] : out.summaries) {
      const size_t to = indexOf(peer);
      ASSERT_LT(to, nodes.size());
      summary.wire_bytes = wireBytes(summary);
      if (delivers(i, to, "backfill")) nodes[to]->station->receive(summary, true);
    }
    for (auto& [peer, reply] : out.features) {
      const size_t to = indexOf(peer);
      ASSERT_LT(to, nodes.size());
      reply.wire_bytes = 100 + (reply.features ? reply.features->descriptors.size() * 60 : 0);
      if (delivers(i, to, "features")) nodes[to]->station->receive(reply);
    }
    if (out.status) {
      const uint64_t bytes = 200 + 80 * out.status->peers.size();
      for (size_t to = 0; to < nodes.size(); ++to) {
        if (to != i && delivers(i, to, "status")) nodes[to]->station->receive(*out.status, bytes);
      }
    }
    n.station->newPeers();  // the link would advertise their topics: nothing to do in memory
    if (dies) restart(i);
  }

  uint64_t unacknowledged(size_t i) {
    uint64_t total = 0;
    for (const auto& [k, v] : nodes[i]->station->report().values) {
      if (endsWith(k, ": loops not yet acknowledged")) total += std::stoull(v);
    }
    return total;
  }

  // SIGKILL and a start on the ledger last saved; the maps are kept as they are (their own
  // persistence is not this test's).
  void restart(size_t i) {
    nodes[i]->station.reset();
    ++nodes[i]->restarts;
    start(i);
  }

  // One round: the clock moves 100 ms, every station works once and its messages go out.
  void round() {
    now += std::chrono::milliseconds(100);
    ++rounds;
    for (size_t i = 0; i < nodes.size(); ++i) {
      if (nodes[i]->station) handle(i, nodes[i]->station->work());
    }
  }

  // The backlog of every station (summaries a peer announced and it has not taken).
  uint64_t backlog() {
    uint64_t total = 0;
    for (auto& n : nodes) {
      if (!n->station) continue;
      for (const auto& [k, v] : n->station->report().values) {
        if (endsWith(k, ": backlog (summaries not yet taken)")) total += std::stoull(v);
      }
    }
    return total;
  }

  // Rounds until every station took every summary, no pull waits and every loop is acknowledged, for
  // 5 s of quiet after. Returns whether it settled within `max_rounds`.
  bool settle(int max_rounds = 3000) {
    int quiet = 0;
    for (int r = 0; r < max_rounds; ++r) {
      round();
      bool settled = backlog() == 0;
      for (auto& n : nodes) settled = settled && n->station && n->station->settled();
      quiet = settled ? quiet + 1 : 0;
      if (quiet >= 50) return true;
    }
    return false;
  }

  // The ledger of node i, as JSON.
  nlohmann::json ledger(size_t i) { return nlohmann::json::parse(nodes[i]->station->ledgerText()); }
};

// What a run found, judged by the ground truth.
struct Findings {
  std::set<int> found;  // bravo's keyframes with a true loop published by their decider
  size_t wrong = 0;
  std::set<LoopKey> decided;  // every loop published by its decider
};

Findings judge(Network& net) {
  Findings f;
  for (auto& n : net.nodes) {
    for (const DecidedLoop& d : n->decided) {
      judgeAccepted(static_cast<int>(d.query_id), d.result.candidates, f.found, f.wrong);
      f.decided.insert(net.peerLoopOf(*n, d).query);
    }
  }
  return f;
}

// Every loop published at most once on each side; every loop taken by its query's station was
// published by its decider; with `both_sides`, also every loop published by its decider was taken.
// Each loop's query is a keyframe of its station's robot as it was decided on: its session and id
// are the map's, and the decider judged it with that keyframe's features (no wrong loop).
void expectPublishedOnceOnEachSide(Network& net, bool both_sides, const std::set<LoopKey>& may_miss = {},
                                   const std::string& at = "") {
  for (auto& n : net.nodes) {
    for (const auto& [key, count] : n->published) {
      EXPECT_EQ(count, 1) << n->name << " published " << keyText(key) << " " << count << " times " << at;
      EXPECT_EQ(key.decider, n->name);
      const size_t q = net.indexOf(key.station);
      ASSERT_LT(q, net.nodes.size());
      Node& query = *net.nodes[q];
      const auto taken = query.taken.find(key);
      if (both_sides && !may_miss.count(key)) {
        EXPECT_TRUE(taken != query.taken.end())
            << keyText(key) << " published by its decider, not by " << query.name << " " << at;
      }
      // The query as stored at its station.
      const auto lock = query.maps->lock();
      const KeyframeMap& map = query.maps->team().robot(0).map();
      const auto index = map.find(key.id);
      ASSERT_TRUE(index.has_value()) << keyText(key) << ": no such keyframe at " << query.name;
      EXPECT_EQ(map.record(*index).session, key.session) << keyText(key);
      EXPECT_EQ(query.robots.at(0), key.robot) << keyText(key);
    }
    for (const auto& [key, count] : n->taken) {
      EXPECT_EQ(count, 1) << n->name << " took " << keyText(key) << " " << count << " times " << at;
      EXPECT_EQ(key.station, n->name);
      const size_t d = net.indexOf(key.decider);
      ASSERT_LT(d, net.nodes.size());
      EXPECT_TRUE(net.nodes[d]->published.count(key) || may_miss.count(key))
          << n->name << " took " << keyText(key) << ", which its decider never published " << at;
    }
  }
}

// Every pair of keyframes of two stations is decided by one of them only: no pair is accepted both
// as a loop of one's keyframe and as a loop of the other's (a loop reported twice, reversed).
void expectNoPairDecidedTwice(Network& net, const std::string& at = "") {
  std::map<std::pair<std::pair<std::string, uint64_t>, std::pair<std::string, uint64_t>>, std::vector<std::string>> by;
  for (auto& n : net.nodes) {
    for (const DecidedLoop& d : n->decided) {
      for (const LoopCandidate& c : d.result.candidates) {
        if (!c.accepted) continue;
        auto a = std::make_pair(d.peer, d.query_id);
        auto b = std::make_pair(n->name, c.id);
        by[std::minmax(a, b)].push_back(n->name);
      }
    }
  }
  for (const auto& [pair, deciders] : by) {
    EXPECT_EQ(deciders.size(), 1u) << "keyframe " << pair.first.second << " of " << pair.first.first << " and keyframe "
                                   << pair.second.second << " of " << pair.second.first << " accepted "
                                   << deciders.size() << " times, first by " << deciders.front() << ", last by "
                                   << deciders.back() << " " << at;
  }
}

// Every summary a station numbered was taken by the other (ledgers: received == own count).
void expectEverySummaryTaken(Network& net, const std::string& at = "") {
  for (size_t a = 0; a < net.nodes.size(); ++a) {
    const nlohmann::json mine = net.ledger(a);
    for (size_t b = 0; b < net.nodes.size(); ++b) {
      if (a == b) continue;
      const nlohmann::json theirs = net.ledger(b);
      const uint64_t received = theirs["received"].value(net.nodes[a]->name, uint64_t{0});
      EXPECT_EQ(received, mine["own"].size())
          << net.nodes[b]->name << " took " << received << " of " << net.nodes[a]->name << "'s " << mine["own"].size()
          << " summaries " << at;
    }
  }
}

// Two stations, alpha (robot1) and bravo (robot2); at step k alpha stores frame k and bravo frame
// 150 + k, then every station works `rounds_per_step` rounds.
struct TwoStations {
  Network net;
  size_t alpha = 0, bravo = 0;
  int rounds_per_step = 2;
  TwoStations() {
    alpha = net.add("alpha", "robot1");
    bravo = net.add("bravo", "robot2");
  }
  void startBoth() {
    net.start(alpha);
    net.start(bravo);
  }
  void step(int k) {
    if (k < kHalf && net.nodes[alpha]->station) net.store(alpha, k);
    if (k < kHalf && net.nodes[bravo]->station) net.store(bravo, kHalf + k);
    for (int r = 0; r < rounds_per_step; ++r) net.round();
  }
};

// The run without faults, once (a reference for the runs with faults).
struct Reference {
  Findings findings;
  std::map<LoopKey, int> published_alpha, taken_bravo;
  bool settled = false;
  uint64_t rounds = 0;
  uint64_t refused = 0, late = 0;
};

const Reference& faultlessRun() {
  static const Reference reference = [] {
    Reference r;
    TwoStations two;
    two.startBoth();
    for (int k = 0; k < kHalf; ++k) two.step(k);
    r.settled = two.net.settle();
    r.rounds = two.net.rounds;
    r.findings = judge(two.net);
    r.published_alpha = two.net.nodes[two.alpha]->published;
    r.taken_bravo = two.net.nodes[two.bravo]->taken;
    expectPublishedOnceOnEachSide(two.net, true, {}, "(no faults)");
    expectNoPairDecidedTwice(two.net, "(no faults)");
    // Nothing was late, nothing refused.
    for (size_t i : {two.alpha, two.bravo}) {
      Node& n = *two.net.nodes[i];
      const std::string peer = n.name == "alpha" ? "bravo" : "alpha";
      r.refused += figure(*n.station, peer + ": refused") + figure(*n.station, "refused from no peer");
      r.late += figure(*n.station, peer + ": loops found late after a reconnect");
    }
    expectEverySummaryTaken(two.net, "(no faults)");
    return r;
  }();
  return reference;
}

std::string listOf(const std::set<int>& s) {
  std::ostringstream out;
  for (int v : s) out << v << " ";
  return out.str();
}

// The faultless run's loops of bravo's keyframes from `first` on that a run with faults did not find.
// A keyframe taken late, or after a peer's restart, is asked of another part of the decider's map
// than when taken at once (what the decider stored meanwhile without knowing of it is its to decide:
// StationLedger::eligiblePrefix), which moves the probability of a marginal loop across the decision
// threshold: at most kMayJudgeOtherwise of them may be judged otherwise. A loop lost by the protocol
// (a summary not taken, a pull or a loop never answered) fails the run's other checks.
constexpr size_t kMayJudgeOtherwise = 2;

std::set<int> notFound(const Findings& f, int first = kHalf) {
  std::set<int> missing;
  for (int q : faultlessRun().findings.found) {
    if (q >= first && !f.found.count(q)) missing.insert(q);
  }
  return missing;
}

// --- two stations on the sample ---

TEST(StationProtocol, TwoStationsFindTheLoopsOneNodeServingBothFindsAndPublishEachOnceOnEachSide) {
  const std::set<int>& single = singleNodeFinds();
  ASSERT_GT(single.size(), 20u);
  const Reference& r = faultlessRun();
  EXPECT_TRUE(r.settled);
  size_t kept = 0;
  for (int q : single) kept += r.findings.found.count(q);
  const double share = static_cast<double>(kept) / static_cast<double>(single.size());
  std::cout << "two stations: " << r.findings.found.size() << " loop queries found (" << kept
            << " of the single node's " << single.size() << ", " << share << "), wrong " << r.findings.wrong << ", "
            << r.findings.decided.size() << " loops published, settled after " << r.rounds << " rounds\n";
  EXPECT_GE(share, 0.95) << "single node: " << listOf(single) << "\nstations: " << listOf(r.findings.found);
  EXPECT_EQ(r.findings.wrong, 0u);
  EXPECT_EQ(r.refused, 0u);
  EXPECT_EQ(r.late, 0u);
  // Each accepted loop published once by its decider (alpha: the queries are bravo's) and once by bravo.
  EXPECT_GE(r.published_alpha.size(), r.findings.found.size());
  EXPECT_EQ(r.published_alpha.size(), r.taken_bravo.size());
  for (const auto& [key, count] : r.published_alpha) {
    EXPECT_EQ(count, 1) << keyText(key);
    EXPECT_EQ(key.station, "bravo");
    EXPECT_EQ(r.taken_bravo.count(key), 1u) << keyText(key) << " not published by bravo";
  }
}

// Links down for random stretches (longer than the peer timeout at times) and 10 % of all messages
// lost: once the links are back and the stations settled, every summary was taken, every loop of the
// faultless run is found (but for kMayJudgeOtherwise marginal ones), none is published twice, and
// every loop its decider published was published by its query's station.
TEST(StationProtocol, RandomOutagesAndLostMessagesLoseNoLoopAndRepeatNone) {
  ASSERT_FALSE(faultlessRun().findings.found.empty());
  std::map<std::string, uint64_t> lost;  // over the runs, by kind
  uint64_t late = 0;                     // loops of keyframes stored during an outage or backfilled
  for (const unsigned seed : {7u, 21u}) {
    TwoStations two;
    two.net.random.seed(seed);
    two.net.drop = 0.10;
    std::mt19937 outages(seed * 1000 + 1);
    two.startBoth();
    int down_until = -1;
    int outage_steps = 0;
    bool disconnected = false;  // alpha reported bravo disconnected (no heartbeat for the peer timeout)
    for (int k = 0; k < kHalf; ++k) {
      if (k >= down_until && two.net.linkUp(two.alpha, two.bravo) == false) two.net.down.clear();
      if (two.net.linkUp(two.alpha, two.bravo) && outages() % 100 < 3) {
        // 1.5 to 9 s: at times beyond the peer timeout (5 s), so that keyframes are stored unreachable.
        down_until = k + 5 + static_cast<int>(outages() % 26);
        two.net.down.insert({two.alpha, two.bravo});
      }
      if (!two.net.linkUp(two.alpha, two.bravo)) ++outage_steps;
      two.step(k);
      disconnected = disconnected || two.net.nodes[two.alpha]->station->report().warn;
    }
    // The links back up, still losing messages for 30 s (the loops decided late go out then), then
    // losing none.
    two.net.down.clear();
    for (int r = 0; r < 300; ++r) two.net.round();
    two.net.drop = 0.0;
    const std::string at = "(seed " + std::to_string(seed) + ")";
    ASSERT_TRUE(two.net.settle()) << at;
    for (const auto& [kind, count] : two.net.lost) lost[kind] += count;
    late += figure(*two.net.nodes[two.alpha]->station, "bravo: loops found late after a reconnect");
    const Findings f = judge(two.net);
    EXPECT_GT(outage_steps, 10) << at;
    EXPECT_TRUE(disconnected) << at;
    EXPECT_FALSE(two.net.nodes[two.alpha]->station->report().warn) << at;
    EXPECT_GT(figure(*two.net.nodes[two.alpha]->station, "bravo: reconnects"), 0u) << at;
    const std::set<int> missing = notFound(f);
    std::cout << "seed " << seed << ": link down for " << outage_steps << " of " << kHalf << " steps, "
              << two.net.dropped << " of " << two.net.messages << " messages lost; " << f.found.size()
              << " loop queries found, wrong " << f.wrong << ", found late "
              << figure(*two.net.nodes[two.alpha]->station, "bravo: loops found late after a reconnect")
              << ", of the faultless run's not found: " << listOf(missing) << "; lost:";
    for (const auto& [kind, count] : two.net.lost) std::cout << " " << count << " " << kind;
    std::cout << "\n";
    EXPECT_LE(missing.size(), kMayJudgeOtherwise)
        << "bravo's keyframes whose loop was not found " << at << ": " << listOf(missing);
    EXPECT_EQ(f.wrong, 0u) << at;
    expectPublishedOnceOnEachSide(two.net, true, {}, at);
    expectNoPairDecidedTwice(two.net, at);
    expectEverySummaryTaken(two.net, at);
  }
  EXPECT_GT(late, 0u) << "loops found late are counted";
  // Every kind of message was lost at some point (else the runs prove less than they say).
  for (const char* kind : {"summary", "backfill", "status", "request", "features", "loop"}) {
    EXPECT_GT(lost[kind], 0u) << kind;
  }
}

// A station killed at some point of the run (between calls, or in the middle of handling a call that
// would persist) and restarted on the ledger it last saved: it rejoins, its summaries are all taken
// by the peer, no loop is published twice on either side, and each names the keyframe it was decided
// on; the loops of the keyframes stored after the restart are found.
struct CrashCase {
  const char* victim;
  int step;  // killed at its first fitting call from this step on
  Kill kill;
};

std::ostream& operator<<(std::ostream& out, const CrashCase& c) {
  return out << c.victim << " at step " << c.step << " " << killName(c.kill);
}

class StationCrash : public ::testing::TestWithParam<CrashCase> {};

TEST_P(StationCrash, ARestartOnTheLastSavedLedgerNeitherLosesLaterLoopsNorRepeatsAny) {
  const CrashCase c = GetParam();
  ASSERT_FALSE(faultlessRun().findings.found.empty());
  TwoStations two;
  two.startBoth();
  const size_t victim = two.net.indexOf(c.victim);
  two.net.crash = Network::CrashPlan{};
  two.net.crash->victim = victim;
  two.net.crash->at = static_cast<uint64_t>(c.step * two.rounds_per_step + 1);  // the step's first round
  two.net.crash->kill = c.kill;
  int killed_in = -1;  // the step
  for (int k = 0; k < kHalf; ++k) {
    two.step(k);
    if (killed_in < 0 && two.net.crash->done) killed_in = k;
  }
  std::ostringstream name;
  name << "(" << c << ")";
  const std::string at = name.str();
  ASSERT_TRUE(two.net.settle()) << at;
  ASSERT_TRUE(two.net.crash->done) << at << ": never killed";
  ASSERT_GE(killed_in, 0);
  const Findings f = judge(two.net);
  std::cout << c << ": killed and restarted in step " << killed_in << ", " << f.found.size() << " loop queries found"
            << ", wrong " << f.wrong << ", " << two.net.crash->lost.size() << " loops lost in the call killed, "
            << two.net.crash->unacknowledged
            << " unacknowledged; of the faultless run's not found: " << listOf(notFound(f)) << "\n";
  EXPECT_EQ(f.wrong, 0u) << at;
  // What may be missing on the query's side: the loops of the call killed after its ledger was
  // written, and the decider's loops unacknowledged at its death (lost with its run, by design).
  std::set<LoopKey> may_miss(two.net.crash->lost.begin(), two.net.crash->lost.end());
  size_t missing_on_query_side = 0;
  for (const auto& [key, count] : two.net.nodes[two.alpha]->published) {
    missing_on_query_side += two.net.nodes[two.bravo]->taken.count(key) == 0 && !may_miss.count(key);
  }
  if (c.victim == std::string("alpha")) {
    EXPECT_LE(missing_on_query_side, two.net.crash->unacknowledged) << at;
  } else {
    EXPECT_EQ(missing_on_query_side, 0u) << at;
  }
  expectPublishedOnceOnEachSide(two.net, false, may_miss, at);
  expectNoPairDecidedTwice(two.net, at);
  expectEverySummaryTaken(two.net, at);
  // The loops of bravo's keyframes stored after the restart (a few steps on: the pulls in flight)
  // are found and published on both sides.
  const std::set<int> missing = notFound(f, kHalf + killed_in + 3);
  EXPECT_LE(missing.size(), kMayJudgeOtherwise)
      << "bravo's keyframes stored after the restart whose loop was not found " << at << ": " << listOf(missing);
  for (const auto& [key, count] : two.net.nodes[two.alpha]->published) {
    if (static_cast<int>(key.id) - kHalf < killed_in + 3) continue;
    EXPECT_EQ(two.net.nodes[two.bravo]->taken.count(key), 1u) << keyText(key) << " " << at;
  }
  EXPECT_EQ(two.net.nodes[victim]->restarts, 1u);
}

INSTANTIATE_TEST_SUITE_P(
    KillPoints, StationCrash,
    ::testing::Values(CrashCase{"alpha", 60, Kill::kAfterHandling}, CrashCase{"alpha", 125, Kill::kAfterHandling},
                      CrashCase{"alpha", 128, Kill::kBeforePersist}, CrashCase{"alpha", 134, Kill::kAfterPersist},
                      CrashCase{"bravo", 60, Kill::kAfterHandling}, CrashCase{"bravo", 126, Kill::kAfterHandling},
                      CrashCase{"bravo", 130, Kill::kBeforePersist}, CrashCase{"bravo", 137, Kill::kAfterPersist}),
    [](const ::testing::TestParamInfo<CrashCase>& info) {
      return std::string(info.param.victim) + "_step" + std::to_string(info.param.step) + "_" +
             killName(info.param.kill);
    });

// bravo starts after alpha stored 100 keyframes: it asks for them (in batches) and the loops are found.
TEST(StationProtocol, AStationStartingLateCatchesUpAndTheLoopsAreFound) {
  ASSERT_FALSE(faultlessRun().findings.found.empty());
  TwoStations two;
  two.net.start(two.alpha);
  constexpr int kLate = 100;
  for (int s = 0; s < kLate + kHalf; ++s) {
    if (s == kLate) two.net.start(two.bravo);
    if (s < kHalf) two.net.store(two.alpha, s);
    if (s >= kLate) two.net.store(two.bravo, kHalf + (s - kLate));
    for (int r = 0; r < two.rounds_per_step; ++r) two.net.round();
  }
  ASSERT_TRUE(two.net.settle());
  const Findings f = judge(two.net);
  std::cout << "bravo late by " << kLate << " keyframes: " << f.found.size() << " loop queries found, wrong " << f.wrong
            << ", of the faultless run's not found: " << listOf(notFound(f)) << "\n";
  const std::set<int> missing = notFound(f);
  EXPECT_LE(missing.size(), kMayJudgeOtherwise) << "bravo's keyframes whose loop was not found: " << listOf(missing);
  EXPECT_EQ(f.wrong, 0u);
  expectPublishedOnceOnEachSide(two.net, true);
  expectNoPairDecidedTwice(two.net);
  expectEverySummaryTaken(two.net);
}

// --- hostile peers, at the Station ---

// Alpha with a few keyframes; bravo, a peer heard from (a heartbeat) whose first summaries alpha took.
struct HostileFixture : ::testing::Test {
  Network net;
  size_t alpha = 0;
  void SetUp() override {
    alpha = net.add("alpha", "robot1");
    net.start(alpha);
    for (int k = 0; k < 5; ++k) net.store(alpha, k);
    station().receive(statusOf("bravo"), 300);
    for (uint64_t seq = 0; seq < 3; ++seq) station().receive(summaryOf("bravo", seq, 200 + seq), false);
    work();
  }
  Station& station() { return *net.nodes[alpha]->station; }
  Outbox work() {
    net.now += std::chrono::milliseconds(100);
    return station().work();
  }
  TeamStatus statusOf(const std::string& name) {
    TeamStatus s;
    s.station = name;
    s.epoch = 77;
    s.summaries = 3;
    s.descriptor_bytes = 32;
    s.peers = {"alpha"};
    s.received = {5};
    s.loops_received = {0};
    return s;
  }
  PlaceSummary summaryOf(const std::string& name, uint64_t seq, int frame) {
    PlaceSummary s;
    s.station = name;
    s.seq = seq;
    s.epoch = 77;
    s.robot = "robot2";
    s.id = static_cast<uint64_t>(frame);
    s.features = static_cast<uint32_t>(sampleFeatures()[frame].descriptors.size());
    s.descriptor_bytes = 32;
    appendDescriptorBytes(strongestDescriptors(sampleFeatures()[frame], 243), s.descriptor_data);
    s.wire_bytes = Network::wireBytes(s);
    return s;
  }
  // bravo's loop for alpha's keyframe `query`, naming bravo's keyframe 200 (announced).
  PeerLoop loopOf(const std::string& decider, uint64_t seq, uint64_t query) {
    PeerLoop l;
    l.decider = decider;
    l.epoch = 77;
    l.seq = seq;
    l.query = LoopKey{"alpha", "robot1", 0, query, decider};
    PeerLoop::Candidate c;
    c.station = decider;
    c.robot = "robot2";
    c.id = 200;
    c.probability = 0.95;
    c.verified = true;
    l.candidates = {c};
    l.published = PublishedLoop{l.query, {200}};
    l.wire_bytes = 1000;
    return l;
  }
  // Every message refused: against a peer, or from no peer.
  uint64_t refusedInAll() {
    uint64_t total = 0;
    for (const auto& [k, v] : station().report().values) {
      if (endsWith(k, ": refused") || k == "refused from no peer") total += std::stoull(v);
    }
    return total;
  }
  uint64_t received(const std::string& peer) {
    return nlohmann::json::parse(station().ledgerText())["received"].value(peer, uint64_t{0});
  }
};

TEST_F(HostileFixture, APeersLoopIsPublishedOnlyFromAPeerForAKeyframeStoredHereWithSoundContent) {
  ASSERT_EQ(received("bravo"), 3u) << "the setup: bravo's summaries taken";
  const uint64_t no_peer = figure(station(), "refused from no peer");
  // A name never heard from: no peer, nothing published, counted.
  station().receive(loopOf("zulu", 0, 1));
  Outbox out = work();
  EXPECT_TRUE(out.taken.empty());
  EXPECT_EQ(figure(station(), "refused from no peer"), no_peer + 1);
  for (const auto& [k, v] : station().report().values) EXPECT_EQ(k.rfind("zulu", 0), std::string::npos) << k;
  // A content problem (peerLoopContentProblem; test_peer_loop_check has each): refused, counted
  // against bravo.
  uint64_t refused = figure(station(), "bravo: refused");
  PeerLoop bad = loopOf("bravo", 0, 1);
  bad.candidates[0].probability = std::numeric_limits<double>::quiet_NaN();
  station().receive(bad);
  out = work();
  EXPECT_TRUE(out.taken.empty());
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused);
  // A query that is not a keyframe stored here (an id alpha never stored; a session it never had).
  station().receive(loopOf("bravo", 1, 4000));
  out = work();
  EXPECT_TRUE(out.taken.empty());
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused);
  PeerLoop other_session = loopOf("bravo", 2, 1);
  other_session.query.session = 3;
  station().receive(other_session);
  out = work();
  EXPECT_TRUE(out.taken.empty());
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused);
  // A query of another station, a robot not here, a candidate bravo never announced.
  PeerLoop not_ours = loopOf("bravo", 3, 1);
  not_ours.query.station = "charlie";
  station().receive(not_ours);
  PeerLoop no_robot = loopOf("bravo", 4, 1);
  no_robot.query.robot = "robot9";
  station().receive(no_robot);
  PeerLoop unannounced = loopOf("bravo", 5, 1);
  unannounced.candidates[0].id = 250;
  station().receive(unannounced);
  out = work();
  EXPECT_TRUE(out.taken.empty());
  refused += 3;
  EXPECT_EQ(figure(station(), "bravo: refused"), refused);
  // The control: a sound loop of bravo's is taken, published once, persisted; a copy is not.
  station().receive(loopOf("bravo", 6, 1));
  out = work();
  ASSERT_EQ(out.taken.size(), 1u);
  EXPECT_EQ(out.taken[0].first, 0u);
  EXPECT_EQ(std::any_cast<const PublishedLoop&>(out.taken[0].second.published).key.id, 1u);
  EXPECT_TRUE(out.taken[0].second.candidates[0].accepted) << "verified at 0.95: accepted here";
  EXPECT_TRUE(out.persist);
  station().receive(loopOf("bravo", 6, 1));
  out = work();
  EXPECT_TRUE(out.taken.empty()) << "a copy (the same number)";
  station().receive(loopOf("bravo", 7, 1));
  out = work();
  EXPECT_TRUE(out.taken.empty()) << "the same loop numbered again (decided again after a crash)";
  EXPECT_EQ(figure(station(), "bravo: duplicates"), 1u);
  EXPECT_EQ(figure(station(), "bravo: refused"), refused);
}

TEST_F(HostileFixture, AMalformedHeartbeatOrASummaryOfAnotherWidthIsRefused) {
  uint64_t refused = figure(station(), "bravo: refused");
  TeamStatus uneven = statusOf("bravo");
  uneven.received = {};
  station().receive(uneven, 300);
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused);
  TeamStatus uneven_loops = statusOf("bravo");
  uneven_loops.loops_from = {1, 2};
  station().receive(uneven_loops, 300);
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused);
  station().receive(statusOf("bravo"), Station::kMaxStatusBytes + 1);
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused) << "oversized";
  // From a station never heard of: its malformed heartbeat makes it no peer its loops are taken from
  // (both refusals counted, against it or as from no peer).
  const uint64_t before = refusedInAll();
  TeamStatus stranger = statusOf("charlie");
  stranger.loops_received = {};
  station().receive(stranger, 300);
  station().receive(loopOf("charlie", 0, 1));
  EXPECT_TRUE(work().taken.empty());
  EXPECT_EQ(refusedInAll(), before + 2) << "its heartbeat and its loop";
  EXPECT_EQ(figure(station(), "refused from no peer") > 0, true);
  for (const auto& [key, value] : station().report().values) {
    EXPECT_NE(key.rfind("charlie:", 0), 0u) << "a malformed heartbeat made a peer (a slot of the 64): " << key;
  }

  // A summary whose descriptors are 64 bytes wide (alpha's are 32): refused, not taken.
  PlaceSummary wide = summaryOf("bravo", 3, 203);
  wide.descriptor_bytes = 64;
  wide.descriptor_data.resize(64 * 100);
  station().receive(wide, false);
  work();
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused);
  EXPECT_EQ(received("bravo"), 3u);
  PlaceSummary unpaired = summaryOf("bravo", 3, 203);
  unpaired.well_formed = false;
  station().receive(unpaired, false);
  work();
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused);
  EXPECT_EQ(received("bravo"), 3u);
  PlaceSummary oversized = summaryOf("bravo", 3, 203);
  oversized.wire_bytes = Station::maxSummaryBytes(kDefaultSummaryBytes) + 1;
  station().receive(oversized, false);
  work();
  EXPECT_EQ(figure(station(), "bravo: refused"), ++refused);
  EXPECT_EQ(received("bravo"), 3u);
  // The control: the same summary, well formed, is taken.
  station().receive(summaryOf("bravo", 3, 203), false);
  work();
  EXPECT_EQ(received("bravo"), 4u);
  EXPECT_EQ(figure(station(), "bravo: refused"), refused);
}

// With a team key, a message whose MAC fails or that replays a counter is refused, counted per
// claimed sender; without one every message is admitted.
TEST_F(HostileFixture, WithAKeyMessagesFailingTheirMacOrReplayingACounterAreRefusedPerClaimedSender) {
  EXPECT_TRUE(station().admit("bravo", "/mild_team/alpha/loops", 5, false)) << "no key: nothing is checked";

  Network keyed;
  const size_t i = keyed.add("alpha", "robot1");
  keyed.nodes[i]->station = std::make_unique<Station>(keyed.settingsOf(*keyed.nodes[i]), *keyed.nodes[i]->maps);
  keyed.nodes[i]->station->start(std::nullopt, true, 5);
  Station& s = *keyed.nodes[i]->station;
  EXPECT_FALSE(s.admit("mallory", "/mild_team/alpha/loops", 1, false));
  EXPECT_FALSE(s.admit("mallory", "/mild_team/alpha/loops", 2, false));
  EXPECT_FALSE(s.admit("bravo", "/mild_team/alpha/loops", 3, false));
  EXPECT_TRUE(s.admit("bravo", "/mild_team/alpha/loops", 10, true));
  EXPECT_FALSE(s.admit("bravo", "/mild_team/alpha/loops", 10, true)) << "a replay";
  EXPECT_FALSE(s.admit("bravo", "/mild_team/alpha/loops", 9, true)) << "an older counter";
  EXPECT_TRUE(s.admit("bravo", "/mild_team/alpha/requests", 9, true)) << "counters are per topic";
  EXPECT_TRUE(s.admit("bravo", "/mild_team/alpha/loops", 11, true));
  EXPECT_TRUE(s.admit("charlie", "/mild_team/alpha/loops", 1, true)) << "counters are per sender";
  const std::string suffix = ": refused, no valid team key MAC or a replay";
  EXPECT_EQ(figure(s, "mallory" + suffix), 2u);
  EXPECT_EQ(figure(s, "bravo" + suffix), 3u);
  for (const auto& [k, v] : s.report().values) EXPECT_NE(k, "charlie" + suffix);
}

// More than max_requests_per_second requests from one peer (a burst of twice as many is allowed)
// are answered busy; as time passes it is served again.
TEST_F(HostileFixture, RequestsBeyondTheRateAreAnsweredBusy) {
  const auto ask = [this](int n) {
    for (int r = 0; r < n; ++r) {
      TeamRequest request;
      request.from = "bravo";
      request.request_id = 1000 + static_cast<uint64_t>(r);
      request.kind = TeamRequest::kFeatures;
      request.robot = "robot1";
      request.id = 2;
      station().receive(request);
    }
    const Outbox out = station().work();  // the clock stands still
    std::map<uint8_t, int> statuses;
    for (const auto& [peer, reply] : out.features) {
      EXPECT_EQ(peer, "bravo");
      ++statuses[reply.status];
      if (reply.status == TeamFeatures::kOk) {
        EXPECT_TRUE(reply.features.has_value());
        EXPECT_EQ(reply.id, 2u);
      }
    }
    return statuses;
  };
  net.now += std::chrono::seconds(10);  // the bucket full: twice the rate
  std::map<uint8_t, int> statuses = ask(60);
  EXPECT_EQ(statuses[TeamFeatures::kOk], 40);
  EXPECT_EQ(statuses[TeamFeatures::kBusy], 20);
  statuses = ask(5);
  EXPECT_EQ(statuses[TeamFeatures::kBusy], 5) << "no time passed";
  net.now += std::chrono::milliseconds(500);  // 10 tokens
  statuses = ask(15);
  EXPECT_EQ(statuses[TeamFeatures::kOk], 10);
  EXPECT_EQ(statuses[TeamFeatures::kBusy], 5);
}

// A stop waits for the pulls still open (Station::settle: their loops would be lost), and no longer
// than it is told: bravo announces the places alpha stored, alpha pulls their features.
TEST_F(HostileFixture, SettleWaitsForOpenPullsAndNoLonger) {
  TeamStatus more = statusOf("bravo");
  more.summaries = 6;
  station().receive(more, 300);
  std::vector<TeamRequest> pulls;
  for (uint64_t seq = 3; seq < 6; ++seq) {
    PlaceSummary same_place = summaryOf("bravo", seq, static_cast<int>(seq) - 2);  // alpha's keyframes 1-3
    same_place.id = 300 + seq;
    station().receive(same_place, false);
    for (const auto& [peer, request] : work().requests) {
      if (request.kind == TeamRequest::kFeatures) pulls.push_back(request);
    }
  }
  ASSERT_FALSE(pulls.empty()) << "the setup: alpha pulls the features of a place it stored";
  ASSERT_EQ(station().pendingPulls(), pulls.size());
  station().drain();
  const auto start = std::chrono::steady_clock::now();
  EXPECT_FALSE(station().settle(std::chrono::milliseconds(60)));
  EXPECT_GE(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(60));
  for (const TeamRequest& pull : pulls) {  // bravo answers: it no longer has them
    TeamFeatures reply;
    reply.from = "bravo";
    reply.request_id = pull.request_id;
    reply.status = TeamFeatures::kUnknown;
    station().receive(reply);
  }
  work();
  EXPECT_EQ(station().pendingPulls(), 0u);
  EXPECT_TRUE(station().settle(std::chrono::milliseconds(0)));
}

TEST(StationProtocolStart, RefusesAnInvalidNameAndAnotherStationsLedger) {
  TestMaps maps({"robot1"});
  StationSettings settings;
  settings.robots = {"robot1"};
  settings.station = "Alpha";
  EXPECT_THROW(Station(settings, maps), InvalidInput);
  settings.station = "bravo";
  Station bravo(settings, maps);
  bravo.start(std::nullopt, false, 3);
  settings.station = "alpha";
  Station alpha(settings, maps);
  EXPECT_THROW(alpha.start(bravo.ledgerText(), false, 4), InvalidInput);
  EXPECT_THROW(alpha.start(std::string("{"), false, 4), InvalidInput);
}

// Keyframe ids given by the node (image input: none in the observation) are never given twice in
// a robot's map, across a crash included: a station restarted on a map saved before its crash (here,
// on none) gives ids above every one its crashed run gave, and so does a map reset while it runs;
// the peers' names for the crashed run's keyframes keep naming those keyframes.
TEST(StationProtocolStart, ARestartOnAnOlderMapGivesNoIdItsCrashedRunGave) {
  StationSettings settings;
  settings.station = "alpha";
  settings.robots = {"robot1"};
  std::string saved;  // what the link writes right after start(), before any keyframe
  std::set<uint64_t> given;
  {
    TestMaps maps({"robot1"});
    Station alpha(settings, maps);
    alpha.start(std::nullopt, false, 5);
    saved = alpha.ledgerText();
    for (int k = 0; k < 30; ++k) {
      const auto lock = maps.lock();
      const DetectionResult r = maps.team().process(Observation::ofFeatures(sampleFeatures()[k], 0.1 * k));
      given.insert(r.query_id);
      alpha.stored(r);
    }
  }  // killed: its map was never saved
  TestMaps maps({"robot1"});
  Station alpha(settings, maps);
  alpha.start(saved, false, 6);
  const auto give = [&](int k) {
    const auto lock = maps.lock();
    const DetectionResult r = maps.team().process(Observation::ofFeatures(sampleFeatures()[k], 0.1 * k));
    alpha.stored(r);
    return r.query_id;
  };
  for (int k = 30; k < 40; ++k) {
    const uint64_t id = give(k);
    EXPECT_EQ(given.count(id), 0u) << "id " << id << " was given before the crash";
    given.insert(id);
  }
  saved = alpha.ledgerText();
  {
    const auto lock = maps.lock();
    maps.team().reset();
    alpha.mapReplaced(0);
  }
  for (int k = 40; k < 45; ++k) {
    const uint64_t id = give(k);
    EXPECT_EQ(given.count(id), 0u) << "id " << id << " was given before the reset";
    given.insert(id);
  }
  EXPECT_TRUE(alpha.work().persist) << "the next block of ids was not saved";
  // A ledger without reserved ids (written before they were kept) gives from the map's own.
  TestMaps fresh({"robot1"});
  Station again(settings, fresh);
  StationLedger old("alpha", 1);
  again.start(old.toText(), false, 7);
  const auto lock = fresh.lock();
  EXPECT_EQ(fresh.team().process(Observation::ofFeatures(sampleFeatures()[0], 0.0)).query_id, 0u);
}

}  // namespace
}  // namespace mild
