#include "mild_lcd/team/station.hpp"

#include <algorithm>
#include <iterator>
#include <thread>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

using Clock = std::chrono::steady_clock;

constexpr size_t kMaxSummaryDescriptors = 10000;
// Requests, replies and loops waiting for work(), in all (it takes them every 100 ms).
constexpr uint64_t kMaxInboxBytes = 64u << 20;
// How unknownKeyframeOf's answer begins when a candidate was not announced (yet).
constexpr const char* kNotAnnounced = "a candidate the decider never announced";
// Asked again when unanswered this long (a message sent before the peer's subscriber connected is
// lost; the link may have dropped it).
constexpr std::chrono::seconds kResendAfter{2};
// Loops resent to one peer per heartbeat, at most (after a long outage many wait).
constexpr size_t kMaxResendsPerTick = 50;
// Loops kept for a peer until it acknowledges them; beyond, its summaries wait.
constexpr size_t kMaxUnacknowledged = 10000;
// A count of loops no run reaches (one a microsecond for 146,000 years): a peer claiming one (as
// taken, or as the lowest it can still send) is refused. Below it, a peer's claim of the lowest
// loop it can still send moves only the count of that peer's loops taken here. No claim moves this
// station's own numbering: each run has an epoch, and peers key what they took by it.
constexpr uint64_t kAbsurdCount = uint64_t{1} << 62;
// A summary's bytes beyond its descriptors: its names (each a station's, at most 32 characters, at
// most kMaxPeers + 1 of each list), counts and fixed fields.
constexpr uint64_t kMaxSummaryOverheadBytes = 16384;
// Keyframe ids reserved per robot at a time (StationLedger::idFloor): the ledger is saved with the
// next block before half of this one is given out.
constexpr uint64_t kIdBlock = 10000;

bool stationNames(const std::vector<std::string>& names) {
  return std::all_of(names.begin(), names.end(), [](const std::string& n) { return validStationName(n); });
}

bool contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

}  // namespace

bool Outbox::empty() const {
  return !persist && published.empty() && taken.empty() && loops.empty() && requests.empty() && summaries.empty() &&
         features.empty() && !status;
}

// The largest summary taken: 4 x summary_bytes of descriptors (every station has the same) and its names.
uint64_t Station::maxSummaryBytes(size_t summary_bytes) { return 4 * summary_bytes + kMaxSummaryOverheadBytes; }

Station::Station(StationSettings settings, StationMaps& maps)
    : settings_(std::move(settings)), maps_(maps), ledger_(settings_.station, settings_.robots.size()) {
  if (!validStationName(settings_.station)) {
    throw InvalidInput("~team/station '" + settings_.station.substr(0, kMaxNameLength) +
                       "' is not a station name: 1 to 32 characters of [a-z0-9_], starting with a letter");
  }
}

void Station::start(const std::optional<std::string>& ledger_text, bool keyed, uint64_t epoch) {
  const auto lock = maps_.lock();
  RobotTeam& team = maps_.team();
  descriptor_bytes_ = team.params().features.descriptorBytes();
  summary_descriptors_ = descriptorsWithin(settings_.summary_bytes, descriptor_bytes_);
  if (ledger_text) {
    ledger_.fromText(*ledger_text);
    for (size_t r = 0; r < settings_.robots.size(); ++r) {
      ledger_.forgetBeyond(r, static_cast<KeyframeIndex>(team.robot(r).map().size()));
    }
  }
  // A run of its own: what peers took of earlier runs (a crash's included) never collides with it.
  ledger_.beginRun(epoch);
  epoch_ = ledger_.epoch();
  // Ids an earlier run may have given out (a crash before its map was saved) are not given again:
  // the keyframes peers heard of keep their names. The link saves the ledger before any is given.
  for (size_t r = 0; r < settings_.robots.size(); ++r) {
    KeyframeMap& map = team.robot(r).map();
    map.raiseNextId(ledger_.idFloor(r));
    ledger_.setIdFloor(r, map.nextId() + kIdBlock);
  }
  keyed_ = keyed;
  std::lock_guard<std::mutex> guard(mutex_);
  rules_.station = settings_.station;
  rules_.max_candidates = static_cast<size_t>(team.params().candidates.max_candidates);
  rules_.max_correspondences = settings_.max_keyframe_features;
  rules_.decision_probability = team.params().scoring.decision_probability;
  last_counter_ = ledger_.counters();
  for (const std::string& name : ledger_.peers()) {
    if (Peer* p = peer(name)) {
      p->taken = ledger_.received(name);
      p->runs = ledger_.summaryRuns(name);
    }
  }
  next_tick_ = settings_.now();
  started_ = true;
}

// The ledger is guarded by the detector lock (the keyframe path numbers its keyframes in it): it is
// copied under that lock and its text made after the lock is released, so that a robot's keyframe
// waits for the copy only (mild_bench_ledger; docs/multi_robot.md, "Limits", has its figures).
std::string Station::ledgerText() {
  const StationLedger copy = [this] {
    const auto lock = maps_.lock();
    {
      std::lock_guard<std::mutex> guard(mutex_);
      ledger_.setCounters(last_counter_);
    }
    return ledger_;
  }();
  return copy.toText();
}

// --- this station's keyframes ---

PlaceSummary Station::stored(const DetectionResult& result) {
  std::vector<std::string> unreachable;  // told in the summary: to them, its loops come late
  {
    std::lock_guard<std::mutex> guard(mutex_);
    for (const auto& [name, p] : peers_) {
      if (p.seen && !connected(p)) unreachable.push_back(name);
    }
  }
  const uint64_t seq = ledger_.recordOwn(result.query_robot, result.query_id, result.query_index, unreachable);
  const uint64_t next = maps_.team().robot(result.query_robot).map().nextId();
  if (next + kIdBlock / 2 >= ledger_.idFloor(result.query_robot)) {
    ledger_.setIdFloor(result.query_robot, next + kIdBlock);  // saved by the next work()
    std::lock_guard<std::mutex> guard(mutex_);
    ids_reserved_ = true;
  }
  return summaryOf(seq);
}

void Station::mapReplaced(size_t robot) {
  ledger_.mapReplaced(robot);
  if (!started_) return;  // start() reserves
  // A reset map would give its ids from 0 again: those its earlier keyframes had are kept.
  KeyframeMap& map = maps_.team().robot(robot).map();
  map.raiseNextId(ledger_.idFloor(robot));
  ledger_.setIdFloor(robot, map.nextId() + kIdBlock);
  std::lock_guard<std::mutex> guard(mutex_);
  ids_reserved_ = true;
}

void Station::sentSummary(uint64_t bytes) {
  std::lock_guard<std::mutex> guard(mutex_);
  ++summaries_out_;
  summary_bytes_out_ += bytes;
}

PlaceSummary Station::summaryOf(uint64_t seq) {
  const StationLedger::Own& own = ledger_.own(seq);
  PlaceSummary s;
  s.station = settings_.station;
  s.seq = seq;
  s.epoch = epoch_;
  s.epoch_start = ledger_.runStart();
  s.robot = settings_.robots.at(own.robot);
  s.id = own.id;
  s.descriptor_bytes = static_cast<uint32_t>(descriptor_bytes_);
  s.known = own.known;
  s.unreachable = own.unreachable;
  const KeyframeMap& map = maps_.team().robot(own.robot).map();
  // A map replaced since (a load, a reset) no longer holds it: the summary goes without
  // descriptors, so that the peer counts it and finds nothing in it.
  if (const auto index = own.id == StationLedger::kNoKeyframe ? std::nullopt : map.find(own.id)) {
    const Features features = map.features(*index);
    s.stamp = map.record(*index).stamp;
    s.session = map.record(*index).session;
    s.looped_by = ledger_.loopedBy(settings_.station, s.robot, s.session, s.id);
    s.features = static_cast<uint32_t>(features.descriptors.size());
    appendDescriptorBytes(strongestDescriptors(features, summary_descriptors_), s.descriptor_data);
  }
  return s;
}

// --- what arrives (any thread: only queued) ---

Station::Peer* Station::peer(const std::string& name) {
  auto it = peers_.find(name);
  if (it != peers_.end()) return &it->second;
  if (name == settings_.station || !validStationName(name) || peers_.size() >= kMaxPeers) return nullptr;
  Peer& p = peers_[name];
  p.tokens = 2.0 * settings_.max_requests_per_second;
  p.refilled = settings_.now();
  new_peers_.push_back(name);
  return &p;
}

bool Station::connected(const Peer& p) const {
  return p.seen && settings_.now() - p.last_seen < std::chrono::duration<double>(settings_.peer_timeout);
}

void Station::refuse(const std::string& name) {
  const auto it = peers_.find(name);
  if (it != peers_.end()) {
    ++it->second.refused;
  } else {
    ++refused_;
  }
}

// Whether a message of p's run `epoch`, which numbers from `start`, is of a run it has not left. A
// new run: what was taken of its numbers from `start` on was an earlier run's, and is taken again
// (StationLedger::summaryRun); what waits of another run is dropped.
bool Station::seeRun(Peer& p, uint64_t epoch, uint64_t start) {
  const PeerRuns::Seen seen = p.runs.see(epoch);
  if (seen != PeerRuns::Seen::kNew) return seen == PeerRuns::Seen::kCurrent;
  p.taken = std::min(p.taken, start);
  for (auto it = p.waiting.begin(); it != p.waiting.end();) {
    it = it->second.summary.epoch == epoch ? std::next(it) : p.waiting.erase(it);
  }
  return true;
}

bool Station::wellFormed(const PlaceSummary& s) const {
  const size_t width = s.descriptor_bytes;
  return s.well_formed && width == static_cast<size_t>(descriptor_bytes_) && width > 0 &&
         s.wire_bytes <= maxSummaryBytes(settings_.summary_bytes) && stationNames(s.unreachable) &&
         s.descriptor_data.size() % width == 0 && s.descriptor_data.size() / width <= kMaxSummaryDescriptors &&
         s.descriptor_data.size() <= 4 * settings_.summary_bytes && s.known.size() <= kMaxPeers + 1 &&
         std::all_of(s.known.begin(), s.known.end(), [](const auto& k) { return validStationName(k.first); }) &&
         s.unreachable.size() <= kMaxPeers + 1 && !s.robot.empty() && s.robot.size() <= kMaxNameLength &&
         s.looped_by.size() <= kMaxPeers + 1 && stationNames(s.looped_by);
}

void Station::receive(PlaceSummary summary, bool backfill) {
  if (summary.station == settings_.station) return;  // our own, broadcast
  std::lock_guard<std::mutex> guard(mutex_);
  // A malformed message makes no peer (forged names would fill the table): it is counted against
  // the peer it names, if one, else against none.
  if (!wellFormed(summary)) {
    const auto it = peers_.find(summary.station);
    if (it != peers_.end()) {
      ++it->second.summaries_in;
      it->second.summary_bytes_in += summary.wire_bytes;
    }
    refuse(summary.station);
    return;
  }
  Peer* p = peer(summary.station);
  if (!p) {
    ++refused_;
    return;
  }
  ++p->summaries_in;
  p->summary_bytes_in += summary.wire_bytes;
  if (!seeRun(*p, summary.epoch, summary.epoch_start) || summary.seq < p->taken) {
    ++p->duplicates;  // of a run it left, or taken already
    return;
  }
  // Ahead of a gap, at most this many wait; later ones are asked for again once the gap is filled.
  // The earliest are kept: they are what the gap's filling lets through next.
  const size_t room = 4 * settings_.backfill_batch + 64;
  if (p->waiting.size() >= room && p->waiting.count(summary.seq) == 0) {
    if (summary.seq > p->waiting.rbegin()->first) return;
    p->waiting.erase(std::prev(p->waiting.end()));
  }
  // Late: sent to fill a gap, or stored by its station while it could not hear from this one.
  const bool late = backfill || contains(summary.unreachable, settings_.station);
  Waiting& waiting = p->waiting[summary.seq];
  waiting = Waiting{std::move(summary), late || waiting.late};
  wake_.notify_one();
}

void Station::receive(const TeamStatus& msg, uint64_t wire_bytes) {
  if (msg.station == settings_.station) return;
  std::lock_guard<std::mutex> guard(mutex_);
  if (wire_bytes > kMaxStatusBytes || msg.peers.size() != msg.received.size() ||
      msg.peers.size() != msg.loops_received.size() || msg.loops_from.size() > msg.peers.size() ||
      msg.loops_epoch.size() > msg.peers.size()) {
    refuse(msg.station);  // makes no peer
    return;
  }
  Peer* p = peer(msg.station);
  if (!p) {
    ++refused_;
    return;
  }
  if (!seeRun(*p, msg.epoch, msg.epoch_start)) return;  // a run it left
  if (!connected(*p) && p->seen) ++p->reconnects;
  p->seen = true;
  p->last_seen = settings_.now();
  p->summaries = msg.summaries;
  p->compatible = msg.descriptor_bytes == static_cast<uint32_t>(descriptor_bytes_);
  for (size_t i = 0; i < msg.peers.size(); ++i) {
    if (msg.peers[i] != settings_.station) continue;
    const uint64_t claim = msg.loops_received[i];
    if (claim >= kAbsurdCount || (i < msg.loops_from.size() && msg.loops_from[i] >= kAbsurdCount)) {
      ++p->refused;
      continue;
    }
    // Our loops it counts are this run's, or none.
    if (i < msg.loops_epoch.size() && msg.loops_epoch[i] == epoch_) p->acknowledged = std::max(p->acknowledged, claim);
    if (i < msg.loops_from.size()) p->loops_from = msg.loops_from[i];
  }
  while (!p->unacknowledged.empty() && p->unacknowledged.front().loop.seq < p->acknowledged) {
    p->unacknowledged.pop_front();
  }
}

// Requests, replies and loops wait in inboxes bounded in count and in bytes, on arrival: a thousand
// messages of a few megabytes each would otherwise wait. An empty inbox takes any one message (a
// whole keyframe's features may be larger than the bound; each is judged when handled).
template <class M>
static bool enqueue(std::deque<M>& inbox, M&& msg, uint64_t bytes, uint64_t& inbox_bytes) {
  if (inbox.size() >= Station::kMaxInbox || (inbox_bytes > 0 && inbox_bytes + bytes > kMaxInboxBytes)) return false;
  inbox_bytes += bytes;
  inbox.push_back(std::move(msg));
  return true;
}

void Station::receive(TeamRequest request) {
  std::lock_guard<std::mutex> guard(mutex_);
  if (!enqueue(requests_, std::move(request), kMaxRequestBytes, inbox_bytes_)) ++refused_;
  wake_.notify_one();
}

void Station::receive(TeamFeatures reply) {
  std::lock_guard<std::mutex> guard(mutex_);
  const uint64_t bytes = reply.wire_bytes;
  if (!enqueue(replies_, std::move(reply), bytes, inbox_bytes_)) ++refused_;
  wake_.notify_one();
}

// Checked and its candidates' `accepted` decided on arrival, off the detector lock, by the same
// rules: a loop refused by its content waits in the inbox as its numbering only, not as the whole
// message it came as.
void Station::receive(PeerLoop loop) {
  std::lock_guard<std::mutex> guard(mutex_);
  loop.content_problem = peerLoopContentProblem(loop, rules_);
  if (!loop.content_problem.empty()) {
    loop.candidates.clear();
    loop.published.reset();
  }
  for (PeerLoop::Candidate& c : loop.candidates) c.accepted = acceptedHere(c, rules_);
  const uint64_t bytes = loop.wire_bytes;
  if (!enqueue(loops_, std::move(loop), bytes, inbox_bytes_)) ++refused_;
  wake_.notify_one();
}

bool Station::admit(const std::string& sender, const std::string& topic, uint64_t counter, bool mac_ok) {
  if (!keyed_) return true;
  std::lock_guard<std::mutex> guard(mutex_);
  bool ok = mac_ok;
  if (ok) {
    // Each sender's messages on one topic come in its order (one connection): a counter not above
    // the last taken is a copy sent again. Only key holders make entries here.
    const std::string stream = sender + " " + topic;
    const auto last = last_counter_.find(stream);
    if (last != last_counter_.end() && counter <= last->second) {
      ok = false;
    } else if (last != last_counter_.end() || last_counter_.size() < StationLedger::kMaxCounters) {
      last_counter_[stream] = counter;
    }
  }
  if (!ok) {
    ++refused_;
    const bool named = unauthenticated_.count(sender) > 0 || unauthenticated_.size() < kMaxPeers;
    ++unauthenticated_[named ? sender.substr(0, kMaxNameLength) : std::string()];
  }
  return ok;
}

void Station::refusedUnread() {
  std::lock_guard<std::mutex> guard(mutex_);
  ++refused_;
  ++refused_unread_;
}

void Station::sent(const std::string& name, uint64_t bytes) {
  std::lock_guard<std::mutex> guard(mutex_);
  const auto it = peers_.find(name);
  if (it != peers_.end()) it->second.bytes_out += bytes;
}

std::vector<std::string> Station::newPeers() {
  std::lock_guard<std::mutex> guard(mutex_);
  return std::exchange(new_peers_, {});
}

// --- the link's thread ---

bool Station::wait(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mutex_);
  if (!halted_) wake_.wait_for(lock, timeout);
  return !halted_;
}

Outbox Station::work() {
  Outbox out;
  std::deque<TeamRequest> requests;
  std::deque<TeamFeatures> replies;
  std::deque<PeerLoop> loops;
  {
    std::lock_guard<std::mutex> guard(mutex_);
    out.persist = std::exchange(ids_reserved_, false);
    requests.swap(requests_);
    replies.swap(replies_);
    loops.swap(loops_);
    inbox_bytes_ = 0;
  }
  // One message that cannot be handled is counted; the others are handled still.
  const auto guarded = [this](const auto& handle) {
    try {
      handle();
    } catch (const std::exception&) {
      std::lock_guard<std::mutex> guard(mutex_);
      ++refused_;
    }
  };
  for (const TeamRequest& r : requests) guarded([&] { serve(r, out); });
  for (TeamFeatures& r : replies) guarded([&] { onFeatures(std::move(r), out); });
  for (PeerLoop& l : loops) guarded([&] { onLoop(std::move(l), out); });
  // A bounded batch, so that requests and replies are not starved by a long backlog.
  for (int i = 0; i < 50; ++i) {
    bool took = false;
    guarded([&] { took = takeNextSummary(out); });
    if (!took) break;
  }
  if (settings_.now() >= next_tick_) {
    tick(out);
    next_tick_ = settings_.now() + std::chrono::seconds(1);
  }
  return out;
}

bool Station::takeNextSummary(Outbox& out) {
  std::string name;
  Waiting next;
  {
    std::lock_guard<std::mutex> guard(mutex_);
    if (draining_) return false;
    for (auto& [n, p] : peers_) {
      // A copy of one taken meanwhile (the broadcast and a gap's filling both brought it).
      while (!p.waiting.empty() && p.waiting.begin()->first < p.taken) p.waiting.erase(p.waiting.begin());
      if (p.waiting.empty() || p.waiting.begin()->first != p.taken || !p.compatible) continue;
      // Backpressure: a peer that does not answer pulls or acknowledge loops is not given more.
      if (p.pending_pulls >= settings_.max_pending_pulls || p.unacknowledged.size() >= kMaxUnacknowledged) continue;
      name = n;
      next = std::move(p.waiting.begin()->second);
      p.waiting.erase(p.waiting.begin());
      break;
    }
  }
  if (name.empty()) return false;
  take(name, next.summary, next.late, out);
  return true;
}

void Station::take(const std::string& name, const PlaceSummary& msg, bool late, Outbox& out) {
  Pending pending;
  pending.peer = name;
  pending.summary = msg;
  pending.summary.descriptor_data.clear();  // read below; not kept while waiting
  pending.late = late;
  {
    const auto lock = maps_.lock();
    {
      std::lock_guard<std::mutex> guard(mutex_);
      Peer* p = peer(name);
      // Of a run the peer left while it waited (a heartbeat of its restart came between): dropped.
      if (!p || p->runs.current != msg.epoch) return;
      ledger_.summaryRun(name, msg.epoch, msg.epoch_start);
      const bool in_turn = ledger_.received(name) == msg.seq;
      // Taken whatever follows: a summary this station cannot use is counted, never asked again.
      if (in_turn) ledger_.took(name);
      p->taken = ledger_.received(name);
      if (!in_turn) return;
    }
    const DescriptorList descriptors =
        descriptorsFromBytes(msg.descriptor_data.data(), msg.descriptor_data.size(), descriptor_bytes_);
    if (descriptors.empty()) return;
    // A keyframe whose loop of ours is held, by the peer or here (decided before a crash): not
    // decided again.
    if (contains(msg.looped_by, settings_.station) ||
        ledger_.holdsLoop({name, msg.robot, msg.session, msg.id, settings_.station})) {
      ledger_.announced(name, msg.robot, msg.session, msg.id);
      return;
    }
    RobotTeam& team = maps_.team();
    const std::string remote = name + "/" + msg.robot;
    const auto last_session = remote_sessions_.find(remote);
    if (last_session != remote_sessions_.end() && last_session->second != msg.session) team.remoteSessionBegan(remote);
    if (remote_sessions_.size() < 4 * RobotTeam::kMaxRemoteRobots) remote_sessions_[remote] = msg.session;
    std::vector<KeyframeIndex> eligible;
    for (size_t r = 0; r < settings_.robots.size(); ++r) {
      eligible.push_back(ledger_.eligiblePrefix(r, static_cast<KeyframeIndex>(team.robot(r).map().size()), msg));
    }
    try {
      pending.answer = team.askRemote(remote, descriptors, msg.features, eligible);
    } catch (const InvalidInput&) {
      std::lock_guard<std::mutex> guard(mutex_);
      refuse(name);  // too many remote robots
      return;
    }
    // A keyframe the peer has (its summary carries descriptors): its loops may name it.
    ledger_.announced(name, msg.robot, msg.session, msg.id);
    pending.replaced = maps_.replaced();
  }
  // Only a candidate that could be accepted is worth the whole keyframe.
  if (!pending.answer.needs_features) return;
  std::lock_guard<std::mutex> guard(mutex_);
  Peer* p = peer(name);
  if (!p) return;
  const uint64_t id = next_request_++;
  ++p->pending_pulls;
  Pending& kept = pending_.emplace(id, std::move(pending)).first->second;
  sendPull(id, kept, out);
}

// Under mutex_.
void Station::sendPull(uint64_t request_id, Pending& pending, Outbox& out) {
  TeamRequest request;
  request.from = settings_.station;
  request.request_id = request_id;
  request.kind = TeamRequest::kFeatures;
  request.robot = pending.summary.robot;
  request.id = pending.summary.id;
  out.requests.emplace_back(pending.peer, std::move(request));
  pending.asked = settings_.now();
}

void Station::onFeatures(TeamFeatures reply, Outbox& out) {
  Pending pending;
  bool verify = false;
  {
    std::lock_guard<std::mutex> guard(mutex_);
    auto it = pending_.find(reply.request_id);
    if (it == pending_.end() || it->second.peer != reply.from) return;  // answered already, or not ours
    Peer* p = peer(reply.from);
    if (!p) return;
    if (reply.status == TeamFeatures::kBusy) return;  // asked again after kResendAfter
    if (reply.status == TeamFeatures::kOk) {
      ++p->features_in;
      p->feature_bytes_in += reply.wire_bytes;
      const auto& f = reply.features;
      verify = f && reply.wire_bytes <= kMaxMessageBytes && f->descriptors.size() <= settings_.max_keyframe_features &&
               (f->declared_bytes == 0 || f->declared_bytes == descriptor_bytes_) &&
               std::all_of(f->descriptors.begin(), f->descriptors.end(),
                           [&](const Descriptor& d) { return d.bytes == descriptor_bytes_; });
      if (!verify) ++p->refused;
    }
    pending = std::move(it->second);
    pending_.erase(it);
    --p->pending_pulls;
  }
  // A keyframe its station no longer has, or features this station cannot use: judged unverified
  // (nothing is accepted without verification).
  judged(pending, verify ? &*reply.features : nullptr, out);
}

void Station::judged(const Pending& pending, const Features* features, Outbox& out) {
  DecidedLoop loop;
  {
    const auto lock = maps_.lock();
    if (maps_.replaced() != pending.replaced) return;  // the candidates were keyframes of a replaced map
    RobotTeam& team = maps_.team();
    loop.result = team.judgeRemote(pending.answer, features);
    for (const LoopCandidate& c : loop.result.candidates) {
      if (c.accepted && !std::count(loop.robots.begin(), loop.robots.end(), c.robot)) loop.robots.push_back(c.robot);
    }
    if (loop.robots.empty()) return;
    loop.result.similarity.clear();  // not sent; kept until acknowledged
    loop.result.unreported.clear();
    loop.peer = pending.peer;
    loop.epoch = epoch_;
    loop.query_robot = pending.summary.robot;
    loop.query_session = pending.summary.session;  // ids repeat across sessions: the pair names it
    loop.query_id = pending.summary.id;
    loop.query_stamp = pending.summary.stamp;
    loop.query_features = pending.summary.features;
    loop.database_size = team.robot(loop.robots.front()).map().size();
    // Held by content: decided once (a copy decided again after a crash is not published).
    if (!ledger_.keepLoop({pending.peer, loop.query_robot, loop.query_session, loop.query_id, settings_.station})) {
      return;
    }
    std::lock_guard<std::mutex> guard(mutex_);
    Peer* p = peer(pending.peer);
    if (!p) return;
    loop.seq = ledger_.nextLoopFor(pending.peer);
    ++p->loops_decided;
    if (pending.late) ++p->loops_found_late;
    p->unacknowledged.push_back({loop, settings_.now()});
  }
  out.persist = true;
  out.loops.push_back(loop);
  out.published.push_back(std::move(loop));
}

// A peer's loop for one of this station's keyframes is published only as this station stored and
// heard it: its query a keyframe stored here for that robot (id and session), its candidates
// keyframes the decider announced, its content sound (peerLoopContentProblem, on arrival),
// `accepted` decided here. A loop refused is counted; when its decider is a peer whose summaries
// this station took, its number is taken too, so that the decider's later loops are not held
// behind it (the decider resends a loop until it is counted).
void Station::onLoop(PeerLoop loop, Outbox& out) {
  const size_t robot = robotIndex(loop.query.robot);
  uint64_t loops_from = 0;
  bool caught_up = false;  // every summary the decider numbered is taken here
  {
    std::lock_guard<std::mutex> guard(mutex_);
    // Only a peer's loops are taken: a name never heard from makes no peer and no ledger entry.
    const auto it = peers_.find(loop.decider);
    if (it == peers_.end() || !it->second.seen || loop.wire_bytes > kMaxMessageBytes) {
      refuse(loop.decider);
      return;
    }
    // The lowest it can still send, as its heartbeat says: of this loop's run only.
    loops_from = it->second.runs.current == loop.epoch ? it->second.loops_from : 0;
    caught_up = it->second.summaries <= it->second.taken;
  }
  const auto lock = maps_.lock();
  std::string problem = loop.content_problem;
  if (problem.empty()) problem = unknownKeyframeOf(loop, robot);
  // A candidate not announced yet, while the decider's summaries are still coming (both stored at
  // once, or a gap being filled): it is resent until its summary is taken here.
  if (!problem.empty() && problem.rfind(kNotAnnounced, 0) == 0 && !caught_up) return;
  // A decider none of whose summaries was taken cannot have decided a loop (its candidates are its
  // keyframes): nothing of it goes into the ledger.
  bool in_turn = false;  // the next of its loops expected here
  bool copy = false;     // one taken already (a resend crossing the acknowledgement)
  if (ledger_.received(loop.decider) > 0) {
    // Numbered per run of the decider: a new run's from 0; a run it left sends no more.
    if (ledger_.loopRun(loop.decider, loop.epoch) == PeerRuns::Seen::kPast) return;
    // In their order only: a later one is dropped and comes again (the decider resends until
    // acknowledged), an earlier one was published already. A decider that can no longer send the
    // next one expected (it restarted, or crashed, with loops unacknowledged) is followed: those
    // loops are lost, and counted. (loops_from is below kAbsurdCount: receive(TeamStatus) refuses more.)
    uint64_t expected = ledger_.loopsReceivedFrom(loop.decider);
    const uint64_t resumes = std::min(loops_from, loop.seq);
    if (resumes > expected) {
      {
        std::lock_guard<std::mutex> guard(mutex_);
        if (Peer* p = peer(loop.decider)) p->loops_lost += resumes - expected;
      }
      ledger_.skipLoopsReceivedTo(loop.decider, resumes);
      expected = resumes;
    }
    in_turn = loop.seq == expected;
    copy = loop.seq < expected;
    if (in_turn) ledger_.tookLoop(loop.decider);
  } else if (problem.empty()) {
    problem = kNotAnnounced;
  }
  std::lock_guard<std::mutex> guard(mutex_);
  if (!problem.empty()) {
    if (!copy) refuse(loop.decider);
    return;
  }
  if (!in_turn) return;
  // Held by content: a loop its decider decided again (after its crash) is taken, not published.
  LoopKey held = loop.query;
  held.decider = loop.decider;
  if (!ledger_.keepLoop(held)) {
    if (Peer* p = peer(loop.decider)) ++p->duplicates;
    return;
  }
  out.persist = true;
  out.taken.emplace_back(robot, std::move(loop));
}

// Under the detector lock: "" when the loop's query is a keyframe this station stored for that robot
// (as the decider names it: id and session) and each candidate one the decider announced; else why not.
std::string Station::unknownKeyframeOf(const PeerLoop& loop, size_t robot) const {
  const LoopKey& q = loop.query;
  if (q.station != settings_.station) return "its query is not this station's";
  if (robot >= settings_.robots.size()) return "no robot '" + q.robot.substr(0, kMaxNameLength) + "' here";
  const KeyframeMap& map = maps_.team().robot(robot).map();
  const auto index = map.find(q.id);
  if (!index || map.record(*index).session != q.session) {
    return "its query, keyframe " + std::to_string(q.id) + " of session " + std::to_string(q.session) + ", is not in " +
           q.robot + "'s map";
  }
  if (loop.candidates.empty()) return "no candidate";
  for (const auto& c : loop.candidates) {
    if (!ledger_.wasAnnounced(loop.decider, c.robot, c.session, c.id)) {
      return std::string(kNotAnnounced) + ": keyframe " + std::to_string(c.id) + " of session " +
             std::to_string(c.session) + " of its robot '" + c.robot.substr(0, kMaxNameLength) + "'";
    }
  }
  return "";
}

size_t Station::robotIndex(const std::string& name) const {
  const auto& names = settings_.robots;
  return static_cast<size_t>(std::find(names.begin(), names.end(), name) - names.begin());
}

void Station::serve(const TeamRequest& request, Outbox& out) {
  {
    std::lock_guard<std::mutex> guard(mutex_);
    Peer* p = peer(request.from);
    if (!p) {
      ++refused_;
      return;
    }
    const auto now = settings_.now();
    const double rate = settings_.max_requests_per_second;
    p->tokens = std::min(2.0 * rate, p->tokens + rate * std::chrono::duration<double>(now - p->refilled).count());
    p->refilled = now;
    if (p->tokens < 1.0) {
      ++p->refused;
      if (request.kind == TeamRequest::kFeatures) {
        TeamFeatures busy;
        busy.from = settings_.station;
        busy.request_id = request.request_id;
        busy.status = TeamFeatures::kBusy;
        busy.reason = "more than ~team/max_requests_per_second requests";
        out.features.emplace_back(request.from, std::move(busy));
      }
      return;
    }
    p->tokens -= 1.0;
  }
  if (request.kind == TeamRequest::kSummaries) {
    const auto lock = maps_.lock();
    const uint64_t end = std::min<uint64_t>(
        ledger_.ownCount(), request.first + std::min<uint64_t>(request.count, settings_.backfill_batch));
    for (uint64_t seq = request.first; seq < end; ++seq) out.summaries.emplace_back(request.from, summaryOf(seq));
    return;
  }
  TeamFeatures reply;
  reply.from = settings_.station;
  reply.request_id = request.request_id;
  reply.id = request.id;
  if (request.kind != TeamRequest::kFeatures) {
    reply.status = TeamFeatures::kMalformed;
    reply.reason = "unknown request kind " + std::to_string(request.kind);
  } else if (const size_t robot = robotIndex(request.robot); robot >= settings_.robots.size()) {
    reply.status = TeamFeatures::kUnknown;
    reply.reason = "no robot '" + request.robot.substr(0, kMaxNameLength) + "' at this station";
  } else {
    const auto lock = maps_.lock();
    const KeyframeMap& map = maps_.team().robot(robot).map();
    if (const auto index = map.find(request.id)) {
      reply.features = map.features(*index);
      reply.status = TeamFeatures::kOk;
    } else {
      reply.status = TeamFeatures::kUnknown;
      reply.reason = "robot '" + request.robot + "' has no keyframe " + std::to_string(request.id);
    }
  }
  std::lock_guard<std::mutex> guard(mutex_);
  if (reply.status != TeamFeatures::kOk) refuse(request.from);
  out.features.emplace_back(request.from, std::move(reply));
}

void Station::tick(Outbox& out) {
  TeamStatus status;
  const auto lock = maps_.lock();
  std::lock_guard<std::mutex> guard(mutex_);
  const RobotTeam& team = maps_.team();
  rules_.max_candidates = static_cast<size_t>(team.params().candidates.max_candidates);
  rules_.decision_probability = team.params().scoring.decision_probability;
  status.station = settings_.station;
  status.epoch = epoch_;
  status.epoch_start = ledger_.runStart();
  status.summaries = ledger_.ownCount();
  status.descriptor_bytes = static_cast<uint32_t>(descriptor_bytes_);
  const auto now = settings_.now();
  for (auto& [name, p] : peers_) {
    status.peers.push_back(name);
    status.received.push_back(ledger_.received(name));
    status.loops_received.push_back(ledger_.loopsReceivedFrom(name));
    status.loops_epoch.push_back(ledger_.loopEpoch(name));
    status.loops_from.push_back(p.unacknowledged.empty() ? ledger_.loopsSentTo(name)
                                                         : p.unacknowledged.front().loop.seq);
    status.summaries_in += p.summaries_in;
    status.summary_bytes_in += p.summary_bytes_in;
    status.features_in += p.features_in;
    status.feature_bytes_in += p.feature_bytes_in;
    status.loops_decided += p.loops_decided;
    status.loops_found_late += p.loops_found_late;
    status.refused += p.refused;
    if (!connected(p) || !p.compatible) continue;
    // Behind, and what is next is not waiting here: ask for it (again, if unanswered).
    const bool gap = p.summaries > p.taken && (p.waiting.empty() || p.waiting.begin()->first != p.taken);
    if (gap && now - p.backfill_asked >= kResendAfter) {
      TeamRequest request;
      request.from = settings_.station;
      request.request_id = next_request_++;
      request.kind = TeamRequest::kSummaries;
      request.first = p.taken;
      request.count = static_cast<uint32_t>(settings_.backfill_batch);
      out.requests.emplace_back(name, std::move(request));
      p.backfill_asked = now;
    }
    // Loops not acknowledged are sent again, in order, a bounded number per second.
    size_t resent = 0;
    for (auto& sent : p.unacknowledged) {
      if (resent == kMaxResendsPerTick) break;
      if (now - sent.at < kResendAfter) continue;
      out.loops.push_back(sent.loop);  // the link gives it a new counter and MAC (a copy is a replay)
      sent.at = now;
      ++resent;
    }
  }
  status.refused += refused_;
  for (auto& [id, pending] : pending_) {
    const auto it = peers_.find(pending.peer);
    if (it != peers_.end() && connected(it->second) && now - pending.asked >= kResendAfter) sendPull(id, pending, out);
  }
  out.status = std::move(status);
}

// --- stopping ---

void Station::drain() {
  std::lock_guard<std::mutex> guard(mutex_);
  draining_ = true;
}

bool Station::settled() {
  std::lock_guard<std::mutex> guard(mutex_);
  if (!pending_.empty()) return false;
  return std::none_of(peers_.begin(), peers_.end(),
                      [this](const auto& p) { return connected(p.second) && !p.second.unacknowledged.empty(); });
}

bool Station::settle(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!settled()) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

size_t Station::pendingPulls() {
  std::lock_guard<std::mutex> guard(mutex_);
  return pending_.size();
}

void Station::halt() {
  {
    std::lock_guard<std::mutex> guard(mutex_);
    halted_ = true;
  }
  wake_.notify_all();
}

StationReport Station::report() {
  StationReport r;
  uint64_t backlog_total = 0;
  size_t disconnected = 0;
  const auto add = [&r](const std::string& key, const auto& value) {
    if constexpr (std::is_convertible_v<decltype(value), std::string>) {
      r.values.emplace_back(key, value);
    } else {
      r.values.emplace_back(key, std::to_string(value));
    }
  };
  std::lock_guard<std::mutex> guard(mutex_);
  for (const auto& [name, p] : peers_) {
    const bool up = connected(p);
    if (!up) ++disconnected;
    const uint64_t backlog = p.summaries > p.taken ? p.summaries - p.taken : 0;
    backlog_total += backlog;
    add(name + ": connected", std::string(up ? "yes" : "no"));
    add(name + ": compatible", std::string(p.compatible ? "yes" : "no (another descriptor width)"));
    add(name + ": backlog (summaries not yet taken)", backlog);
    add(name + ": keyframes waiting for features", p.pending_pulls);
    add(name + ": bytes in (summaries)", p.summary_bytes_in);
    add(name + ": bytes in (features pulled)", p.feature_bytes_in);
    add(name + ": bytes out", p.bytes_out);
    add(name + ": loops decided", p.loops_decided);
    add(name + ": loops found late after a reconnect", p.loops_found_late);
    add(name + ": loops not yet acknowledged", p.unacknowledged.size());
    add(name + ": its loops lost to its restart", p.loops_lost);
    add(name + ": refused", p.refused);
    add(name + ": duplicates", p.duplicates);
    add(name + ": reconnects", p.reconnects);
  }
  add("summaries sent", summaries_out_);
  add("summary bytes sent", summary_bytes_out_);
  add("refused from no peer", refused_);
  add("refused unread (oversized, or another type)", refused_unread_);
  add("team key",
      std::string(keyed_ ? "yes: messages without its MAC, and replays, are refused"
                         : "NO: anyone who can publish on /mild_team/ can inject loops (set ~team/key_file)"));
  for (const auto& [claimed, count] : unauthenticated_) {
    add((claimed.empty() ? std::string("(other names)") : claimed) + ": refused, no valid team key MAC or a replay",
        count);
  }
  r.warn = disconnected > 0;
  r.summary = r.warn ? std::to_string(disconnected) + " of " + std::to_string(peers_.size()) + " peers disconnected, " +
                           std::to_string(backlog_total) + " summaries behind"
                     : std::to_string(peers_.size()) + " peers connected, " + std::to_string(backlog_total) +
                           " summaries behind";
  return r;
}

}  // namespace mild
