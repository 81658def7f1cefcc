#include "mild_lcd/team/station_ledger.hpp"

#include <algorithm>
#include <filesystem>
#include <random>
#include <tuple>

#include <nlohmann/json.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/io/database_directory.hpp"

namespace mild {

bool validStationName(const std::string& name) {
  if (name.empty() || name.size() > 32 || !(name[0] >= 'a' && name[0] <= 'z')) return false;
  return std::all_of(name.begin(), name.end(),
                     [](char c) { return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_'; });
}

PeerRuns::Seen PeerRuns::see(uint64_t epoch) {
  if (current == epoch) return Seen::kCurrent;
  if (std::find(past.begin(), past.end(), epoch) != past.end()) return Seen::kPast;
  if (current) past.push_back(*current);
  if (past.size() > kMaxPast) past.erase(past.begin());
  current = epoch;
  return Seen::kNew;
}

bool LoopKey::operator<(const LoopKey& o) const {
  return std::tie(station, robot, session, id, decider) < std::tie(o.station, o.robot, o.session, o.id, o.decider);
}

StationLedger::StationLedger(std::string station, size_t robots)
    : station_(std::move(station)), robots_(robots), numbered_(robots) {
  if (!validStationName(station_)) {
    throw InvalidInput("station name '" + station_ + "' is not 1-32 characters of [a-z0-9_] starting with a letter");
  }
  if (robots_ == 0) throw InvalidInput("a station needs at least one robot");
}

uint64_t StationLedger::recordOwn(size_t robot, uint64_t id, KeyframeIndex map_index,
                                  std::vector<std::string> unreachable) {
  if (robot >= robots_) throw InvalidInput("no robot " + std::to_string(robot));
  Own entry;
  entry.robot = robot;
  entry.id = id;
  entry.unreachable = std::move(unreachable);
  for (const auto& [peer, count] : received_) entry.known.emplace_back(peer, count);
  const uint64_t seq = own_.size();
  own_.push_back(std::move(entry));
  numbered_[robot].push_back({map_index, seq});
  return seq;
}

uint64_t StationLedger::received(const std::string& peer) const {
  const auto it = received_.find(peer);
  return it == received_.end() ? 0 : it->second;
}

void StationLedger::took(const std::string& peer) { ++received_[peer]; }

std::vector<std::string> StationLedger::peers() const {
  std::vector<std::string> names;
  for (const auto& [peer, count] : received_) names.push_back(peer);
  return names;
}

uint64_t StationLedger::knownOf(uint64_t seq, const std::string& peer) const {
  for (const auto& [name, count] : own_[seq].known) {
    if (name == peer) return count;
  }
  return 0;
}

void StationLedger::announced(const std::string& peer, const std::string& robot, uint32_t session, uint64_t id) {
  announced_[peer][robot].emplace(session, id);
}

bool StationLedger::wasAnnounced(const std::string& peer, const std::string& robot, uint32_t session,
                                 uint64_t id) const {
  const auto of_peer = announced_.find(peer);
  if (of_peer == announced_.end()) return false;
  const auto of_robot = of_peer->second.find(robot);
  return of_robot != of_peer->second.end() && of_robot->second.count({session, id}) > 0;
}

KeyframeIndex StationLedger::eligiblePrefix(size_t robot, KeyframeIndex map_size, const PlaceSummary& summary) const {
  if (robot >= robots_) throw InvalidInput("no robot " + std::to_string(robot));
  const std::vector<Numbered>& numbered = numbered_[robot];
  // How many of ours the peer held when it stored the summary's keyframe: ours numbered below
  // that came first (the peer decides nothing about them: we do).
  uint64_t peer_held = 0;
  for (const auto& [name, count] : summary.known) {
    if (name == station_) peer_held = count;
  }
  // Both conditions hold for a prefix of the numbered keyframes (numbers and what we knew only
  // grow along a map), so each ends where it first fails.
  const auto before_peer_knew =
      std::partition_point(numbered.begin(), numbered.end(), [&](const Numbered& n) { return n.seq < peer_held; });
  auto eligible_end = before_peer_knew;
  if (station_ < summary.station) {
    // Stored without knowing of the summary's keyframe, and the peer did not know of ours: neither
    // came first, and the station whose name sorts first (this one) decides.
    const auto concurrent_end = std::partition_point(numbered.begin(), numbered.end(), [&](const Numbered& n) {
      return knownOf(n.seq, summary.station) <= summary.seq;
    });
    eligible_end = std::max(eligible_end, concurrent_end);
  }
  if (eligible_end == numbered.end()) return map_size;
  return std::min(map_size, eligible_end->map_index);
}

void StationLedger::mapReplaced(size_t robot) {
  if (robot >= robots_) throw InvalidInput("no robot " + std::to_string(robot));
  numbered_[robot].clear();
}

void StationLedger::forgetBeyond(size_t robot, KeyframeIndex map_size) {
  if (robot >= robots_) throw InvalidInput("no robot " + std::to_string(robot));
  std::vector<Numbered>& numbered = numbered_[robot];
  numbered.erase(
      std::partition_point(numbered.begin(), numbered.end(), [&](const Numbered& n) { return n.map_index < map_size; }),
      numbered.end());
}

uint64_t StationLedger::nextLoopFor(const std::string& peer) { return loops_sent_[peer]++; }

uint64_t StationLedger::loopsSentTo(const std::string& peer) const {
  const auto it = loops_sent_.find(peer);
  return it == loops_sent_.end() ? 0 : it->second;
}

uint64_t StationLedger::loopsReceivedFrom(const std::string& peer) const {
  const auto it = loops_received_.find(peer);
  return it == loops_received_.end() ? 0 : it->second;
}

void StationLedger::tookLoop(const std::string& peer) { ++loops_received_[peer]; }

void StationLedger::skipLoopsReceivedTo(const std::string& peer, uint64_t count) {
  uint64_t& received = loops_received_[peer];
  received = std::max(received, count);
}

uint64_t StationLedger::drawEpoch() {
  std::random_device device;
  uint64_t epoch = 0;
  while (epoch == 0) epoch = (uint64_t{device()} << 32) ^ device();  // 0: a message of no run
  return epoch;
}

void StationLedger::beginRun(uint64_t epoch) {
  epoch_ = epoch;
  run_start_ = own_.size();
  loops_sent_.clear();  // each run numbers its loops from 0: peers key them by its epoch
}

PeerRuns::Seen StationLedger::summaryRun(const std::string& peer, uint64_t epoch, uint64_t start) {
  const PeerRuns::Seen seen = summary_runs_[peer].see(epoch);
  if (seen == PeerRuns::Seen::kNew) {
    uint64_t& count = received_[peer];
    count = std::min(count, start);
  }
  return seen;
}

PeerRuns::Seen StationLedger::loopRun(const std::string& peer, uint64_t epoch) {
  const PeerRuns::Seen seen = loop_runs_[peer].see(epoch);
  if (seen == PeerRuns::Seen::kNew) loops_received_[peer] = 0;
  return seen;
}

PeerRuns StationLedger::summaryRuns(const std::string& peer) const {
  const auto it = summary_runs_.find(peer);
  return it == summary_runs_.end() ? PeerRuns{} : it->second;
}

uint64_t StationLedger::loopEpoch(const std::string& peer) const {
  const auto it = loop_runs_.find(peer);
  return it == loop_runs_.end() ? 0 : it->second.current.value_or(0);
}

bool StationLedger::keepLoop(const LoopKey& key) {
  if (!loops_kept_.insert(key).second) return false;
  loops_order_.push_back(key);
  if (loops_order_.size() > kMaxLoopsKept) {
    loops_kept_.erase(loops_order_.front());
    loops_order_.pop_front();
  }
  return true;
}

std::vector<std::string> StationLedger::loopedBy(const std::string& station, const std::string& robot, uint32_t session,
                                                 uint64_t id) const {
  std::vector<std::string> deciders;
  const LoopKey first{station, robot, session, id, ""};
  for (auto it = loops_kept_.lower_bound(first); it != loops_kept_.end() && it->station == station &&
                                                 it->robot == robot && it->session == session && it->id == id;
       ++it) {
    deciders.push_back(it->decider);
  }
  return deciders;
}

namespace {

nlohmann::json runsToJson(const std::map<std::string, PeerRuns>& runs) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [peer, r] : runs) j[peer] = {{"current", r.current.value_or(0)}, {"past", r.past}};
  return j;
}

std::map<std::string, PeerRuns> runsFromJson(const nlohmann::json& j) {
  std::map<std::string, PeerRuns> runs;
  for (const auto& [peer, r] : j.items()) {
    PeerRuns& runs_of = runs[peer];
    // 0: no run heard (toText writes an empty current so; no run draws 0).
    if (const auto current = r.at("current").get<uint64_t>(); current != 0) runs_of.current = current;
    runs_of.past = r.at("past").get<std::vector<uint64_t>>();
    if (runs_of.past.size() > PeerRuns::kMaxPast) throw InvalidInput("the ledger keeps too many runs of a peer");
  }
  return runs;
}

}  // namespace

void StationLedger::setIdFloor(size_t robot, uint64_t floor) {
  if (robot >= robots_) throw InvalidInput("no robot " + std::to_string(robot) + " in the ledger");
  if (id_floors_.size() < robots_) id_floors_.resize(robots_, 0);
  id_floors_[robot] = floor;
}

std::string StationLedger::toText() const {
  nlohmann::json j;
  j["format"] = "mild_lcd station ledger 1";
  j["station"] = station_;
  j["robots"] = robots_;
  nlohmann::json own = nlohmann::json::array();
  for (const Own& o : own_) {
    own.push_back({{"robot", o.robot}, {"id", o.id}, {"known", o.known}, {"unreachable", o.unreachable}});
  }
  j["own"] = std::move(own);
  nlohmann::json numbered = nlohmann::json::array();
  for (const auto& list : numbered_) {
    nlohmann::json l = nlohmann::json::array();
    for (const Numbered& n : list) l.push_back({n.map_index, n.seq});
    numbered.push_back(std::move(l));
  }
  j["numbered"] = std::move(numbered);
  j["received"] = received_;
  j["loops_sent"] = loops_sent_;
  j["loops_received"] = loops_received_;
  j["announced"] = announced_;
  j["epoch"] = epoch_;
  j["summary_runs"] = runsToJson(summary_runs_);
  j["loop_runs"] = runsToJson(loop_runs_);
  nlohmann::json kept = nlohmann::json::array();
  for (const LoopKey& k : loops_order_) kept.push_back({k.station, k.robot, k.session, k.id, k.decider});
  j["loops_kept"] = std::move(kept);
  j["id_floors"] = id_floors_;
  j["counters"] = counters_;
  return j.dump();
}

void StationLedger::fromText(const std::string& text) {
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    if (j.at("format") != "mild_lcd station ledger 1") throw InvalidInput("not a station ledger");
    if (j.at("station").get<std::string>() != station_) {
      throw InvalidInput("the ledger is station '" + j.at("station").get<std::string>() + "'s, not '" + station_ +
                         "'s");
    }
    if (j.at("robots").get<size_t>() != robots_) throw InvalidInput("the ledger has another number of robots");
    std::vector<Own> own;
    for (const auto& o : j.at("own")) {
      Own entry;
      entry.robot = o.at("robot").get<size_t>();
      entry.id = o.at("id").get<uint64_t>();
      entry.known = o.at("known").get<std::vector<std::pair<std::string, uint64_t>>>();
      entry.unreachable = o.at("unreachable").get<std::vector<std::string>>();
      if (entry.robot >= robots_) throw InvalidInput("a keyframe of robot " + std::to_string(entry.robot));
      own.push_back(std::move(entry));
    }
    std::vector<std::vector<Numbered>> numbered;
    for (const auto& list : j.at("numbered")) {
      std::vector<Numbered> l;
      for (const auto& n : list) {
        const Numbered entry{n.at(0).get<KeyframeIndex>(), n.at(1).get<uint64_t>()};
        if (entry.seq >= own.size() ||
            (!l.empty() && (entry.seq <= l.back().seq || entry.map_index <= l.back().map_index)))
          throw InvalidInput("the ledger's numbering is not increasing");
        l.push_back(entry);
      }
      numbered.push_back(std::move(l));
    }
    if (numbered.size() != robots_) throw InvalidInput("the ledger has another number of robots");
    auto received = j.at("received").get<std::map<std::string, uint64_t>>();
    auto loops_sent = j.at("loops_sent").get<std::map<std::string, uint64_t>>();
    auto loops_received = j.at("loops_received").get<std::map<std::string, uint64_t>>();
    // Absent from ledgers written before peers' announcements were kept: then none are known, and
    // a peer's loop naming a keyframe it announced before is refused (counted).
    std::map<std::string, std::map<std::string, KeyframeKeys>> announced;
    if (j.contains("announced")) announced = j.at("announced").get<decltype(announced)>();
    // Absent from ledgers written before runs and loops were kept: no peer's run known (the first
    // heard is new), no loop held.
    std::map<std::string, PeerRuns> summary_runs, loop_runs;
    if (j.contains("summary_runs")) summary_runs = runsFromJson(j.at("summary_runs"));
    if (j.contains("loop_runs")) loop_runs = runsFromJson(j.at("loop_runs"));
    std::set<LoopKey> loops_kept;
    std::deque<LoopKey> loops_order;
    if (j.contains("loops_kept")) {
      for (const auto& k : j.at("loops_kept")) {
        LoopKey key{k.at(0).get<std::string>(), k.at(1).get<std::string>(), k.at(2).get<uint32_t>(),
                    k.at(3).get<uint64_t>(), k.at(4).get<std::string>()};
        if (loops_kept.insert(key).second) loops_order.push_back(std::move(key));
      }
      if (loops_order.size() > kMaxLoopsKept) throw InvalidInput("the ledger keeps too many loops");
    }
    const uint64_t epoch = j.contains("epoch") ? j.at("epoch").get<uint64_t>() : 0;
    // Absent from ledgers written before ids were reserved: none reserved.
    std::vector<uint64_t> id_floors;
    if (j.contains("id_floors")) id_floors = j.at("id_floors").get<std::vector<uint64_t>>();
    if (id_floors.size() > robots_) throw InvalidInput("the ledger has another number of robots");
    std::map<std::string, uint64_t> counters;
    if (j.contains("counters")) counters = j.at("counters").get<std::map<std::string, uint64_t>>();
    if (counters.size() > kMaxCounters) throw InvalidInput("the ledger keeps too many counters");
    own_ = std::move(own);
    numbered_ = std::move(numbered);
    received_ = std::move(received);
    loops_sent_ = std::move(loops_sent);
    loops_received_ = std::move(loops_received);
    announced_ = std::move(announced);
    summary_runs_ = std::move(summary_runs);
    loop_runs_ = std::move(loop_runs);
    loops_kept_ = std::move(loops_kept);
    loops_order_ = std::move(loops_order);
    epoch_ = epoch;  // the run that saved it, until beginRun
    id_floors_ = std::move(id_floors);
    counters_ = std::move(counters);
    run_start_ = own_.size();
  } catch (const nlohmann::json::exception& e) {
    throw InvalidInput(std::string("the station ledger is malformed: ") + e.what());
  }
}

std::optional<std::string> readLedgerFile(const std::string& path) {
  if (!std::filesystem::is_directory(std::filesystem::path(path).parent_path())) return std::nullopt;
  const ConfinedFile file = fileAtPath(path);
  if (!file.exists()) return std::nullopt;
  return file.readText();
}

void writeLedgerFile(const std::string& path, const std::string& text) {
  // How every ledger text begins (toText: a JSON object): ConfinedFile::replace marks its temporary
  // files with it.
  fileAtPath(path).replaceText(text, "{\"");
}

}  // namespace mild
