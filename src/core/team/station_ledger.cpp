#include "mild_lcd/team/station_ledger.hpp"

#include <algorithm>

#include <nlohmann/json.hpp>

#include "mild_lcd/common/errors.hpp"

namespace mild {

bool validStationName(const std::string& name) {
  if (name.empty() || name.size() > 32 || !(name[0] >= 'a' && name[0] <= 'z')) return false;
  return std::all_of(name.begin(), name.end(),
                     [](char c) { return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_'; });
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

void StationLedger::skipTo(uint64_t count) {
  while (own_.size() < count) {
    Own skipped;
    skipped.id = kNoKeyframe;
    own_.push_back(std::move(skipped));
  }
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

void StationLedger::skipLoopsTo(const std::string& peer, uint64_t count) {
  uint64_t& sent = loops_sent_[peer];
  sent = std::max(sent, count);
}

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
    own_ = std::move(own);
    numbered_ = std::move(numbered);
    received_ = std::move(received);
    loops_sent_ = std::move(loops_sent);
    loops_received_ = std::move(loops_received);
    announced_ = std::move(announced);
  } catch (const nlohmann::json::exception& e) {
    throw InvalidInput(std::string("the station ledger is malformed: ") + e.what());
  }
}

}  // namespace mild
