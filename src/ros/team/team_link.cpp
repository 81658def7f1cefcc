#include "mild_lcd/ros/team/team_link.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <iterator>
#include <string_view>

#include <ros/serialization.h>
#include <topic_tools/shape_shifter.h>
#include <boost/make_shared.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/io/database_directory.hpp"
#include "mild_lcd/ros/messages/message_conversions.hpp"
#include "mild_lcd/ros/team/peer_loop.hpp"

namespace mild_lcd {
namespace {

using Clock = std::chrono::steady_clock;

// A peer's message larger than this is refused: a whole keyframe of 10,000 features of 64 bytes
// with keypoints is well under 2 MB.
constexpr size_t kMaxMessageBytes = 4u << 20;
// Requests, replies and loops waiting for the link's thread, in all (it takes them every 100 ms).
constexpr uint64_t kMaxInboxBytes = 64u << 20;
constexpr size_t kMaxSummaryDescriptors = 10000;
constexpr size_t kMaxNameLength = 64;
// How unknownKeyframeOf's answer begins when a candidate was not announced (yet).
constexpr const char* kNotAnnounced = "a candidate the decider never announced";
// Asked again when unanswered this long (a message published before the peer's subscriber
// connected is lost; the link may have dropped it).
constexpr std::chrono::seconds kResendAfter{2};
// Loops resent to one peer per heartbeat period, at most (after a long outage many wait).
constexpr size_t kMaxResendsPerTick = 50;
// Loops kept for a peer until it acknowledges them; beyond, its summaries wait.
constexpr size_t kMaxUnacknowledged = 10000;
// A count of loops no run reaches (one a microsecond for 146,000 years): a peer claiming one (as
// taken, or as the lowest it can still send) is refused. Below it, a peer's claim of the lowest
// loop it can still send moves only the count of that peer's loops taken here, at once
// (StationLedger::skipLoopsReceivedTo). No claim moves this station's own numbering: each run has
// an epoch, and peers key what they took by it (StationLedger::summaryRun, loopRun).
constexpr uint64_t kAbsurdCount = uint64_t{1} << 62;
// A summary's bytes beyond its descriptors: its names (each a station's, at most 32 characters, at
// most kMaxPeers + 1 of each list), counts and fixed fields.
constexpr size_t kMaxSummaryOverheadBytes = 16384;
// The largest summary taken: 4 x ~team/summary_bytes of descriptors (give every station the same
// value) and its names.
uint64_t maxSummaryBytes(uint64_t summary_bytes) { return 4 * summary_bytes + kMaxSummaryOverheadBytes; }
// A heartbeat: its station's name, fixed fields, and per peer (at most kMaxPeers of them, and the
// station itself) a name of at most 32 characters and three counts.
constexpr uint64_t kMaxStatusBytes = 16384;
// A request: two names and fixed fields.
constexpr uint64_t kMaxRequestBytes = 4096;

// How every ledger text (StationLedger::toText: a JSON object) begins: ConfinedFile::replace marks
// its temporary files with it.
constexpr std::string_view kLedgerSignature = "{\"";

void writeWhole(int fd, const std::string& text) {
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::pwrite(fd, text.data() + done, text.size() - done, static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw mild::IoError("cannot write the station ledger: " + std::string(std::strerror(errno)));
    done += static_cast<size_t>(n);
  }
}

std::string readWhole(const mild::ConfinedFile& file) {
  unsigned long long size = 0;
  const int fd = file.openForReading(size);
  std::string text(size, '\0');
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::read(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    done += static_cast<size_t>(n);
  }
  ::close(fd);
  if (done != text.size()) throw mild::IoError("cannot read the station ledger " + file.display());
  return text;
}

// Who a message says sent it: what its MAC binds, and what its failures are counted against.
const std::string& senderOf(const mild_lcd::PlaceSummary& m) { return m.station; }
const std::string& senderOf(const mild_lcd::TeamStatus& m) { return m.station; }
const std::string& senderOf(const mild_lcd::TeamRequest& m) { return m.from; }
const std::string& senderOf(const mild_lcd::TeamFeatures& m) { return m.from; }
const std::string& senderOf(const mild_lcd::TeamLoop& m) { return m.decider; }

// What the team key's MAC covers: the topic, then the message as serialised with `mac` empty (its
// sender, content, numbering and counter).
template <class M>
std::vector<uint8_t> macInput(M msg, const std::string& topic) {
  msg.mac.clear();
  std::vector<uint8_t> bytes(topic.begin(), topic.end());
  bytes.push_back(0);
  const size_t start = bytes.size();
  bytes.resize(start + ros::serialization::serializationLength(msg));
  ros::serialization::OStream stream(bytes.data() + start, static_cast<uint32_t>(bytes.size() - start));
  ros::serialization::serialize(stream, msg);
  return bytes;
}

template <class M>
uint64_t bytesOf(const M& msg) {
  return ros::serialization::serializationLength(msg);
}

std::string topic(const std::string& station, const std::string& name) { return "/mild_team/" + station + "/" + name; }

// The robots' names on the wire: a station serving one robot (named "") calls it by its own name.
std::vector<std::string> wireNames(std::vector<std::string> names, const std::string& station) {
  for (std::string& n : names) {
    if (n.empty()) n = station;
  }
  return names;
}

// A loop as held (StationLedger::keepLoop): its query as named, and its decider.
mild::LoopKey heldAs(const mild_lcd::LoopClosure& loop, const std::string& decider) {
  return {loop.query_station, loop.query_robot, loop.query_session, loop.query_id, decider};
}

mild::PlaceSummary coreSummary(const mild_lcd::PlaceSummary& msg) {
  mild::PlaceSummary s;
  s.station = msg.station;
  s.seq = msg.seq;
  s.robot = msg.robot;
  s.id = msg.id;
  s.features = msg.features;
  for (size_t i = 0; i < msg.known_stations.size() && i < msg.known_counts.size(); ++i) {
    s.known.emplace_back(msg.known_stations[i], msg.known_counts[i]);
  }
  return s;
}

}  // namespace

TeamLink::TeamLink(ros::NodeHandle nh, const NodeSettings& settings, SharedDetector& shared,
                   std::vector<std::string> robot_names, std::string ledger_path, std::string key_file,
                   PublishLoop publish)
    : nh_(std::move(nh)),
      settings_(settings),
      shared_(shared),
      robot_names_(wireNames(std::move(robot_names), settings.team_station)),
      ledger_path_(std::move(ledger_path)),
      key_file_(std::move(key_file)),
      // Above every counter of this station's earlier runs (a run sends far fewer than a message a
      // nanosecond), so that a restart's messages are not taken for replays.
      next_counter_(static_cast<uint64_t>(
          std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
              .count())),
      publish_(std::move(publish)),
      ledger_(settings.team_station, robot_names_.size()) {
  descriptor_bytes_ = shared_.team->params().features.descriptorBytes();
  summary_descriptors_ = mild::descriptorsWithin(static_cast<size_t>(settings_.team_summary_bytes), descriptor_bytes_);
}

TeamLink::~TeamLink() { stop(); }

// The messages of `name` are taken as bytes (topic_tools::ShapeShifter) and deserialised only when
// of type M and at most max_bytes: a larger one is refused and counted unread, so that no peer's
// message is multiplied in memory by deserialising it (a TeamStatus of 240 MB of empty names once
// took a station to 2.2 GB). roscpp itself still holds a message's bytes until it is handled.
template <class M>
ros::Subscriber TeamLink::subscribeBounded(const std::string& name, uint32_t queue, uint64_t max_bytes,
                                           void (TeamLink::*handle)(const typename M::ConstPtr&)) {
  const boost::function<void(const topic_tools::ShapeShifter::ConstPtr&)> take =
      [this, name, max_bytes, handle](const topic_tools::ShapeShifter::ConstPtr& raw) {
        typename M::ConstPtr msg;
        if (raw->size() <= max_bytes && raw->getDataType() == ros::message_traits::datatype<M>() &&
            raw->getMD5Sum() == ros::message_traits::md5sum<M>()) {
          try {
            msg = raw->instantiate<M>();
          } catch (const std::exception&) {
            msg.reset();  // bytes that are not an M: refused below
          }
        }
        if (msg && !authentic(*msg, name, senderOf(*msg))) return;
        if (!msg) {
          {
            std::lock_guard<std::mutex> guard(mutex_);
            ++refused_;
            ++refused_unread_;
          }
          ROS_WARN_STREAM_THROTTLE(10.0, "team link: a message of "
                                             << raw->size() << " bytes of type '" << raw->getDataType() << "' on "
                                             << name << " refused unread (at most " << max_bytes << " bytes of "
                                             << ros::message_traits::datatype<M>() << ")");
          return;
        }
        (this->*handle)(msg);
      };
  return nh_.subscribe<topic_tools::ShapeShifter>(name, queue, take, ros::VoidConstPtr(),
                                                  ros::TransportHints().tcpNoDelay());
}

void TeamLink::start() {
  // start() runs on the worker (after the start-up load) and stop() on the nodelet's shutdown: one
  // at a time, and nothing started once stopped (the subscribers and the thread are theirs).
  std::lock_guard<std::mutex> lifecycle(lifecycle_);
  if (stopped_) return;
  if (!key_file_.empty()) {
    key_ = mild::TeamKey::fromFile(key_file_);
  } else {
    ROS_WARN_STREAM(
        "team link: no team key (~team/key_file): anyone who can publish on /mild_team/ can inject loops "
        "and take this station's numbers (docs/multi_robot.md, \"The team key\")");
  }
  if (!ledger_path_.empty() && settings_.load_on_start &&
      std::filesystem::is_directory(std::filesystem::path(ledger_path_).parent_path())) {
    // Read as the maps are: a link, a FIFO or a device at its name is refused (never followed, never
    // waited on), and the link stays off rather than write over it.
    const mild::ConfinedFile file = mild::fileAtPath(ledger_path_);
    if (file.exists()) {
      const std::string text = readWhole(file);
      const auto lock = shared_.lock();
      ledger_.fromText(text);
      for (size_t r = 0; r < robot_names_.size(); ++r) {
        ledger_.forgetBeyond(r, static_cast<mild::KeyframeIndex>(shared_.robot(r).map().size()));
      }
    }
  }
  {
    const auto lock = shared_.lock();
    // A run of its own: what peers took of earlier runs (a crash's included) never collides with it.
    ledger_.beginRun(mild::StationLedger::drawEpoch());
    epoch_ = ledger_.epoch();
    std::lock_guard<std::mutex> guard(mutex_);
    for (const std::string& name : ledger_.peers()) {
      if (Peer* p = peer(name)) {
        p->taken = ledger_.received(name);
        p->runs = ledger_.summaryRuns(name);
      }
    }
  }
  const std::string& me = settings_.team_station;
  summaries_pub_ = nh_.advertise<mild_lcd::PlaceSummary>("/mild_team/summaries", 1000);
  status_pub_ = nh_.advertise<mild_lcd::TeamStatus>("/mild_team/status", 10);
  // Each message's size is checked before it is deserialised (subscribeBounded).
  const uint64_t summary_bytes = maxSummaryBytes(static_cast<uint64_t>(settings_.team_summary_bytes));
  summaries_sub_ =
      subscribeBounded<mild_lcd::PlaceSummary>("/mild_team/summaries", 1000, summary_bytes, &TeamLink::onSummary);
  backfill_sub_ =
      subscribeBounded<mild_lcd::PlaceSummary>(topic(me, "summaries"), 1000, summary_bytes, &TeamLink::onBackfill);
  status_sub_ = subscribeBounded<mild_lcd::TeamStatus>("/mild_team/status", 100, kMaxStatusBytes, &TeamLink::onStatus);
  requests_sub_ =
      subscribeBounded<mild_lcd::TeamRequest>(topic(me, "requests"), 1000, kMaxRequestBytes, &TeamLink::onRequest);
  features_sub_ =
      subscribeBounded<mild_lcd::TeamFeatures>(topic(me, "features"), 100, kMaxMessageBytes, &TeamLink::onFeaturesMsg);
  loops_sub_ = subscribeBounded<mild_lcd::TeamLoop>(topic(me, "loops"), 1000, kMaxMessageBytes, &TeamLink::onLoopMsg);
  thread_ = std::thread([this] { run(); });
  started_ = true;
}

void TeamLink::stop() {
  std::lock_guard<std::mutex> lifecycle(lifecycle_);
  stopped_ = true;
  // Keyframes of peers waiting for their features were taken already: their loops would be lost
  // with a restart. Their answers are waited for a moment (a pull takes milliseconds on a live link).
  // So are the acknowledgements of loops sent to connected peers (a restart forgets them).
  const auto deadline = Clock::now() + std::chrono::seconds(3);
  for (;;) {
    {
      std::lock_guard<std::mutex> guard(mutex_);
      draining_ = true;
      bool waiting_for_acknowledgements = false;
      for (const auto& [name, p] : peers_) {
        waiting_for_acknowledgements = waiting_for_acknowledgements || (connected(p) && !p.unacknowledged.empty());
      }
      if ((pending_.empty() && !waiting_for_acknowledgements) || stopping_ || !thread_.joinable()) break;
      if (Clock::now() >= deadline) {
        ROS_WARN_STREAM("team link: stopping with " << pending_.size()
                                                    << " peer keyframes still waiting for their features: their loops, "
                                                       "if any, are not found");
        break;
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  summaries_sub_.shutdown();
  backfill_sub_.shutdown();
  status_sub_.shutdown();
  requests_sub_.shutdown();
  features_sub_.shutdown();
  loops_sub_.shutdown();
  {
    std::lock_guard<std::mutex> guard(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void TeamLink::save() {
  if (ledger_path_.empty() || !started_) return;
  std::string text;
  {
    const auto lock = shared_.lock();
    text = ledger_.toText();
  }
  // The maps' writer: a temporary file of its own (never through a link planted in the folder),
  // flushed to disk, renamed over the ledger, which must be a regular file (a link or a FIFO at its
  // name is refused, never followed or waited on): a crash leaves the previous ledger whole.
  mild::fileAtPath(ledger_path_).replace([&text](int fd) { writeWhole(fd, text); }, kLedgerSignature);
}

void TeamLink::persist() {
  if (!settings_.save_on_shutdown) return;
  try {
    save();
  } catch (const std::exception& e) {
    ROS_WARN_STREAM_THROTTLE(10.0, "team link: could not save the station ledger after a loop: " << e.what());
  }
}

// --- this station's keyframes ---

void TeamLink::stored(const mild::DetectionResult& result) {
  if (!started_) return;                 // off: nothing numbered, nothing sent
  std::vector<std::string> unreachable;  // told in the summary: to them, its loops come late
  {
    std::lock_guard<std::mutex> guard(mutex_);
    for (const auto& [name, p] : peers_) {
      if (p.seen && !connected(p)) unreachable.push_back(name);
    }
  }
  const uint64_t seq = ledger_.recordOwn(result.query_robot, result.query_id, result.query_index, unreachable);
  const mild_lcd::PlaceSummary::Ptr msg = summaryOf(seq);
  sign(*msg, summaries_pub_.getTopic());
  summaries_pub_.publish(msg);
  std::lock_guard<std::mutex> guard(mutex_);
  ++summaries_out_;
  summary_bytes_out_ += bytesOf(*msg);
}

void TeamLink::mapReplaced(size_t robot) { ledger_.mapReplaced(robot); }

mild_lcd::PlaceSummary::Ptr TeamLink::summaryOf(uint64_t seq) {
  const mild::StationLedger::Own& own = ledger_.own(seq);
  auto msg = boost::make_shared<mild_lcd::PlaceSummary>();
  msg->station = settings_.team_station;
  msg->seq = seq;
  msg->epoch = epoch_;
  msg->epoch_start = ledger_.runStart();
  msg->robot = robot_names_.at(own.robot);
  msg->id = own.id;
  msg->descriptor_bytes = static_cast<uint32_t>(descriptor_bytes_);
  for (const auto& [peer, count] : own.known) {
    msg->known_stations.push_back(peer);
    msg->known_counts.push_back(count);
  }
  msg->unreachable = own.unreachable;
  const mild::KeyframeMap& map = shared_.robot(own.robot).map();
  // A map replaced since (a load, a reset) no longer holds it: the summary goes without
  // descriptors, so that the peer counts it and finds nothing in it.
  if (const auto index = own.id == mild::StationLedger::kNoKeyframe ? std::nullopt : map.find(own.id)) {
    const mild::Features features = map.features(*index);
    msg->stamp = stampOf(map.record(*index).stamp);
    msg->session = map.record(*index).session;
    msg->looped_by = ledger_.loopedBy(settings_.team_station, msg->robot, msg->session, msg->id);
    msg->features = static_cast<uint32_t>(features.descriptors.size());
    mild::appendDescriptorBytes(mild::strongestDescriptors(features, summary_descriptors_), msg->descriptors);
  }
  return msg;
}

// A peer's inbox topic before the link's thread has advertised it (shortly after its first sight):
// what would go there is not sent, as if lost on the way; the protocol sends it again (resends,
// re-asked gaps and pulls).
template <class M>
void TeamLink::sign(M& msg, const std::string& topic) {
  msg.counter = next_counter_++;
  msg.mac.clear();
  if (!key_) return;
  const std::vector<uint8_t> bytes = macInput(msg, topic);
  const mild::TeamKey::Mac mac = key_->mac(bytes.data(), bytes.size());
  msg.mac.assign(mac.begin(), mac.end());
}

template <class M>
void TeamLink::sendTo(const ros::Publisher& to, M& msg) {
  if (!to) return;
  sign(msg, to.getTopic());
  to.publish(msg);
}

template <class M>
bool TeamLink::authentic(const M& msg, const std::string& topic, const std::string& sender) {
  if (!key_) return true;
  const std::vector<uint8_t> bytes = macInput(msg, topic);
  bool ok = key_->verify(bytes.data(), bytes.size(), msg.mac.data(), msg.mac.size());
  std::lock_guard<std::mutex> guard(mutex_);
  if (ok) {
    // Each sender's messages on one topic come in its order (one connection): a counter not above
    // the last taken is a copy sent again. Only key holders make entries here.
    const std::string stream = sender + " " + topic;
    const auto last = last_counter_.find(stream);
    if (last != last_counter_.end() && msg.counter <= last->second) {
      ok = false;
    } else if (last != last_counter_.end() || last_counter_.size() < 64 * (kMaxPeers + 1)) {
      last_counter_[stream] = msg.counter;
    }
  }
  if (!ok) {
    ++refused_;
    const bool named = unauthenticated_.count(sender) > 0 || unauthenticated_.size() < kMaxPeers;
    ++unauthenticated_[named ? sender.substr(0, kMaxNameLength) : std::string()];
    ROS_WARN_STREAM_THROTTLE(10.0, "team link: a message on " << topic << " claiming to be from '"
                                                              << sender.substr(0, kMaxNameLength)
                                                              << "' refused: no valid team key MAC, or a replay");
  }
  return ok;
}

void TeamLink::advertiseNewPeers() {
  std::vector<std::string> names;
  {
    std::lock_guard<std::mutex> guard(mutex_);
    for (const auto& [name, p] : peers_) {
      if (!p.advertised) names.push_back(name);
    }
  }
  for (const std::string& name : names) {  // no lock held: each advertise waits for the master
    ros::Publisher requests = nh_.advertise<mild_lcd::TeamRequest>(topic(name, "requests"), 1000);
    ros::Publisher summaries = nh_.advertise<mild_lcd::PlaceSummary>(topic(name, "summaries"), 1000);
    ros::Publisher features = nh_.advertise<mild_lcd::TeamFeatures>(topic(name, "features"), 100);
    ros::Publisher loops = nh_.advertise<mild_lcd::TeamLoop>(topic(name, "loops"), 1000);
    std::lock_guard<std::mutex> guard(mutex_);
    Peer& p = peers_.at(name);  // peers are kept for the run
    p.to_requests = requests;
    p.to_summaries = summaries;
    p.to_features = features;
    p.to_loops = loops;
    p.advertised = true;
  }
}

// --- what arrives (callbacks: they only queue) ---

TeamLink::Peer* TeamLink::peer(const std::string& name) {
  auto it = peers_.find(name);
  if (it != peers_.end()) return &it->second;
  if (name == settings_.team_station || !mild::validStationName(name) || peers_.size() >= kMaxPeers) return nullptr;
  Peer& p = peers_[name];
  // Its inbox topics are advertised by the link's thread (advertiseNewPeers), within 100 ms: not
  // here, under mutex_, which the worker may wait for while it holds the detector lock, and
  // advertising waits for the ROS master.
  p.tokens = 2.0 * settings_.team_max_requests_per_second;
  p.refilled = Clock::now();
  return &p;
}

bool TeamLink::connected(const Peer& p) const {
  return p.seen && Clock::now() - p.last_seen < std::chrono::duration<double>(settings_.team_peer_timeout);
}

void TeamLink::onSummary(const mild_lcd::PlaceSummary::ConstPtr& msg) { queueSummary(msg, false); }
void TeamLink::onBackfill(const mild_lcd::PlaceSummary::ConstPtr& msg) { queueSummary(msg, true); }

// Under mutex_: whether a message of p's run `epoch`, which numbers from `start`, is of a run it has not
// left. A new run: what was taken of its numbers from `start` on was an earlier run's, and is taken
// again (StationLedger::summaryRun); what waits of another run is dropped.
bool TeamLink::seeRun(Peer& p, uint64_t epoch, uint64_t start) {
  const mild::PeerRuns::Seen seen = p.runs.see(epoch);
  if (seen != mild::PeerRuns::Seen::kNew) return seen == mild::PeerRuns::Seen::kCurrent;
  p.taken = std::min(p.taken, start);
  for (auto it = p.waiting.begin(); it != p.waiting.end();) {
    it = it->second.summary->epoch == epoch ? std::next(it) : p.waiting.erase(it);
  }
  return true;
}

void TeamLink::queueSummary(const mild_lcd::PlaceSummary::ConstPtr& msg, bool backfill) {
  if (msg->station == settings_.team_station) return;  // our own, broadcast
  const uint64_t bytes = bytesOf(*msg);
  std::lock_guard<std::mutex> guard(mutex_);
  Peer* p = peer(msg->station);
  if (!p) {
    ++refused_;
    return;
  }
  ++p->summaries_in;
  p->summary_bytes_in += bytes;
  const size_t width = msg->descriptor_bytes;
  const auto station_names = [](const std::vector<std::string>& names) {
    return std::all_of(names.begin(), names.end(), [](const std::string& n) { return mild::validStationName(n); });
  };
  const bool well_formed =
      width == static_cast<size_t>(descriptor_bytes_) && bytes <= kMaxMessageBytes &&
      bytes <= maxSummaryBytes(static_cast<uint64_t>(settings_.team_summary_bytes)) &&
      station_names(msg->known_stations) && station_names(msg->unreachable) && msg->descriptors.size() % width == 0 &&
      msg->descriptors.size() / width <= kMaxSummaryDescriptors &&
      msg->descriptors.size() <= 4 * static_cast<size_t>(settings_.team_summary_bytes) &&
      msg->known_stations.size() == msg->known_counts.size() && msg->known_stations.size() <= kMaxPeers + 1 &&
      msg->unreachable.size() <= kMaxPeers + 1 && !msg->robot.empty() && msg->robot.size() <= kMaxNameLength &&
      msg->looped_by.size() <= kMaxPeers + 1 && station_names(msg->looped_by);
  if (!well_formed) {
    ++p->refused;
    return;
  }
  if (!seeRun(*p, msg->epoch, msg->epoch_start) || msg->seq < p->taken) {
    ++p->duplicates;  // of a run it left, or taken already
    return;
  }
  // Ahead of a gap, at most this many wait; later ones are asked for again once the gap is filled.
  // The earliest are kept: they are what the gap's filling lets through next.
  const size_t room = 4 * static_cast<size_t>(settings_.team_backfill_batch) + 64;
  if (p->waiting.size() >= room && p->waiting.count(msg->seq) == 0) {
    if (msg->seq > p->waiting.rbegin()->first) return;
    p->waiting.erase(std::prev(p->waiting.end()));
  }
  // Late: sent to fill a gap, or stored by its station while it could not hear from this one.
  const bool late = backfill || std::find(msg->unreachable.begin(), msg->unreachable.end(), settings_.team_station) !=
                                    msg->unreachable.end();
  Waiting& waiting = p->waiting[msg->seq];
  waiting = Waiting{msg, late || waiting.late};
  wake_.notify_one();
}

void TeamLink::onStatus(const mild_lcd::TeamStatus::ConstPtr& msg) {
  if (msg->station == settings_.team_station) return;
  std::lock_guard<std::mutex> guard(mutex_);
  Peer* p = peer(msg->station);
  if (!p || msg->peers.size() != msg->received.size() || msg->peers.size() != msg->loops_received.size() ||
      msg->loops_from.size() > msg->peers.size() || msg->loops_epoch.size() > msg->peers.size()) {
    if (p)
      ++p->refused;
    else
      ++refused_;
    return;
  }
  if (!seeRun(*p, msg->epoch, msg->epoch_start)) return;  // a run it left
  if (!connected(*p) && p->seen) ++p->reconnects;
  p->seen = true;
  p->last_seen = Clock::now();
  p->summaries = msg->summaries;
  p->compatible = msg->descriptor_bytes == static_cast<uint32_t>(descriptor_bytes_);
  for (size_t i = 0; i < msg->peers.size(); ++i) {
    if (msg->peers[i] != settings_.team_station) continue;
    const uint64_t claim = msg->loops_received[i];
    if (claim >= kAbsurdCount || (i < msg->loops_from.size() && msg->loops_from[i] >= kAbsurdCount)) {
      ++p->refused;
      continue;
    }
    // Our loops it counts are this run's, or none.
    if (i < msg->loops_epoch.size() && msg->loops_epoch[i] == epoch_)
      p->acknowledged = std::max(p->acknowledged, claim);
    if (i < msg->loops_from.size()) p->loops_from = msg->loops_from[i];
  }
  while (!p->unacknowledged.empty() && p->unacknowledged.front().loop->seq < p->acknowledged) {
    p->unacknowledged.pop_front();
  }
}

template <class Ptr>
void TeamLink::queue(std::deque<Ptr>& inbox, const Ptr& msg) {
  // Bounded in bytes as well as in count, on arrival: a thousand messages of a few megabytes each
  // would otherwise wait for the thread. An empty inbox takes any one message (a whole keyframe's
  // features may be larger than the bound; each handler judges its own message's size).
  const uint64_t bytes = bytesOf(*msg);
  std::lock_guard<std::mutex> guard(mutex_);
  if (inbox.size() >= kMaxInbox || (inbox_bytes_ > 0 && inbox_bytes_ + bytes > kMaxInboxBytes)) {
    ++refused_;
    return;
  }
  inbox_bytes_ += bytes;
  inbox.push_back(msg);
  wake_.notify_one();
}

void TeamLink::onRequest(const mild_lcd::TeamRequest::ConstPtr& msg) { queue(requests_, msg); }

void TeamLink::onFeaturesMsg(const mild_lcd::TeamFeatures::ConstPtr& msg) { queue(replies_, msg); }

void TeamLink::onLoopMsg(const mild_lcd::TeamLoop::ConstPtr& msg) { queue(loops_, msg); }

// --- the link's thread ---

void TeamLink::run() {
  auto next_tick = Clock::now();
  for (;;) {
    std::deque<mild_lcd::TeamRequest::ConstPtr> requests;
    std::deque<mild_lcd::TeamFeatures::ConstPtr> replies;
    std::deque<mild_lcd::TeamLoop::ConstPtr> loops;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait_for(lock, std::chrono::milliseconds(100));
      if (stopping_) return;
      requests.swap(requests_);
      replies.swap(replies_);
      loops.swap(loops_);
      inbox_bytes_ = 0;
    }
    try {
      advertiseNewPeers();
    } catch (const std::exception& e) {
      ROS_WARN_STREAM_THROTTLE(5.0, "team link: " << e.what());
    }
    // One message that cannot be handled is counted; the others are handled still.
    const auto guarded = [this](const auto& handle) {
      try {
        handle();
      } catch (const std::exception& e) {
        {
          std::lock_guard<std::mutex> guard(mutex_);
          ++refused_;
        }
        ROS_WARN_STREAM_THROTTLE(5.0, "team link: " << e.what());
      }
    };
    try {
      for (const auto& r : requests) guarded([&] { serve(r); });
      for (const auto& r : replies) guarded([&] { onFeatures(r); });
      for (const auto& l : loops) guarded([&] { onLoop(l); });
      // A bounded batch, so that requests and replies are not starved by a long backlog.
      for (int i = 0; i < 50 && takeNextSummary(); ++i) {
      }
      if (Clock::now() >= next_tick) {
        tick();
        next_tick = Clock::now() + std::chrono::seconds(1);
      }
    } catch (const std::exception& e) {
      ROS_WARN_STREAM_THROTTLE(5.0, "team link: " << e.what());
    }
  }
}

bool TeamLink::takeNextSummary() {
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
      if (p.pending_pulls >= static_cast<size_t>(settings_.team_max_pending_pulls)) continue;
      if (p.unacknowledged.size() >= kMaxUnacknowledged) continue;
      name = n;
      next = p.waiting.begin()->second;
      p.waiting.erase(p.waiting.begin());
      break;
    }
  }
  if (name.empty()) return false;
  take(name, next.summary, next.late);
  return true;
}

void TeamLink::take(const std::string& name, const mild_lcd::PlaceSummary::ConstPtr& msg, bool late) {
  Pending pending;
  pending.peer = name;
  pending.summary = msg;
  pending.late = late;
  bool asked = false;
  {
    const auto lock = shared_.lock();
    {
      std::lock_guard<std::mutex> guard(mutex_);
      Peer* p = peer(name);
      // Of a run the peer left while it waited (a heartbeat of its restart came between): dropped.
      if (!p || p->runs.current != msg->epoch) return;
      ledger_.summaryRun(name, msg->epoch, msg->epoch_start);
      const bool in_turn = ledger_.received(name) == msg->seq;
      // Taken whatever follows: a summary this station cannot use is counted, never asked again.
      if (in_turn) ledger_.took(name);
      p->taken = ledger_.received(name);
      if (!in_turn) return;
    }
    const mild::DescriptorList descriptors =
        mild::descriptorsFromBytes(msg->descriptors.data(), msg->descriptors.size(), descriptor_bytes_);
    if (descriptors.empty()) return;
    // A keyframe whose loop of ours is held, by the peer or here (decided before a crash): not
    // decided again.
    const std::vector<std::string>& by = msg->looped_by;
    if (std::find(by.begin(), by.end(), settings_.team_station) != by.end() ||
        ledger_.holdsLoop({name, msg->robot, msg->session, msg->id, settings_.team_station})) {
      ledger_.announced(name, msg->robot, msg->session, msg->id);
      return;
    }
    const mild::PlaceSummary summary = coreSummary(*msg);
    const std::string remote = name + "/" + msg->robot;
    const auto last_session = remote_sessions_.find(remote);
    if (last_session != remote_sessions_.end() && last_session->second != msg->session) {
      shared_.team->remoteSessionBegan(remote);
    }
    if (remote_sessions_.size() < 4 * mild::RobotTeam::kMaxRemoteRobots) remote_sessions_[remote] = msg->session;
    std::vector<mild::KeyframeIndex> eligible;
    for (size_t r = 0; r < robot_names_.size(); ++r) {
      eligible.push_back(
          ledger_.eligiblePrefix(r, static_cast<mild::KeyframeIndex>(shared_.robot(r).map().size()), summary));
    }
    try {
      pending.answer = shared_.team->askRemote(remote, descriptors, msg->features, eligible);
    } catch (const mild::InvalidInput&) {
      std::lock_guard<std::mutex> guard(mutex_);
      if (Peer* p = peer(name)) ++p->refused;  // too many remote robots
      return;
    }
    // A keyframe the peer has (its summary carries descriptors): its loops may name it.
    ledger_.announced(name, msg->robot, msg->session, msg->id);
    pending.replaced = shared_.replaced;
    asked = pending.answer.needs_features;
  }
  // Only a candidate that could be accepted is worth the whole keyframe.
  if (!asked) return;
  std::lock_guard<std::mutex> guard(mutex_);
  Peer* p = peer(name);
  if (!p) return;
  const uint64_t id = next_request_++;
  ++p->pending_pulls;
  Pending& stored = pending_.emplace(id, std::move(pending)).first->second;
  sendPull(id, stored);
}

// Under mutex_.
void TeamLink::sendPull(uint64_t request_id, Pending& pending) {
  Peer* p = peer(pending.peer);
  if (!p) return;
  mild_lcd::TeamRequest request;
  request.from = settings_.team_station;
  request.request_id = request_id;
  request.kind = mild_lcd::TeamRequest::FEATURES;
  request.robot = pending.summary->robot;
  request.id = pending.summary->id;
  sendTo(p->to_requests, request);
  p->bytes_out += bytesOf(request);
  pending.asked = Clock::now();
  ++pending.attempts;
}

void TeamLink::onFeatures(const mild_lcd::TeamFeatures::ConstPtr& reply) {
  Pending pending;
  mild::Features features;
  bool verify = false;
  {
    std::lock_guard<std::mutex> guard(mutex_);
    auto it = pending_.find(reply->request_id);
    if (it == pending_.end() || it->second.peer != reply->from) return;  // answered already, or not ours
    Peer* p = peer(reply->from);
    if (!p) return;
    if (reply->status == mild_lcd::TeamFeatures::BUSY) return;  // asked again after kResendAfter
    if (reply->status == mild_lcd::TeamFeatures::OK) {
      ++p->features_in;
      p->feature_bytes_in += bytesOf(*reply);
      try {
        features = featuresFromTeamReply(*reply);  // with its keypoints' precision, the detection scale
        mild::checkCameraAndDepths(features);
        verify = features.descriptors.size() <= static_cast<size_t>(settings_.max_keyframe_features) &&
                 (features.declared_bytes == 0 || features.declared_bytes == descriptor_bytes_) &&
                 std::all_of(features.descriptors.begin(), features.descriptors.end(),
                             [&](const mild::Descriptor& d) { return d.bytes == descriptor_bytes_; });
      } catch (const std::exception&) {
        verify = false;
      }
      if (!verify) ++p->refused;
    }
    pending = std::move(it->second);
    pending_.erase(it);
    --p->pending_pulls;
  }
  // A keyframe its station no longer has, or features this station cannot use: judged unverified
  // (nothing is accepted without verification).
  judged(pending, verify ? &features : nullptr);
}

void TeamLink::judged(const Pending& pending, const mild::Features* features) {
  mild_lcd::LoopClosure::Ptr msg;
  std::vector<size_t> robots;  // whose maps hold an accepted candidate: the loop is theirs too
  {
    const auto lock = shared_.lock();
    if (shared_.replaced != pending.replaced) return;  // the candidates were keyframes of a replaced map
    const mild::DetectionResult result = shared_.team->judgeRemote(pending.answer, features);
    for (const mild::LoopCandidate& c : result.candidates) {
      if (c.accepted && std::find(robots.begin(), robots.end(), c.robot) == robots.end()) robots.push_back(c.robot);
    }
    if (robots.empty()) return;
    std_msgs::Header header;
    header.stamp = pending.summary->stamp;
    msg = boost::make_shared<mild_lcd::LoopClosure>(loopClosureToMsg(
        result, header, shared_.robot(robots.front()).map().size(), settings_.publish_correspondences, robot_names_));
    msg->query_id = pending.summary->id;
    msg->query_session = pending.summary->session;  // ids repeat across sessions: the pair names it
    msg->query_robot = pending.summary->robot;
    msg->query_station = pending.peer;
    msg->features = static_cast<int32_t>(pending.summary->features);
    for (auto& c : msg->candidates) c.station = settings_.team_station;
    // Held by content: decided once (a copy decided again after a crash is not published).
    if (!ledger_.keepLoop(heldAs(*msg, settings_.team_station))) return;
    auto loop = boost::make_shared<mild_lcd::TeamLoop>();
    loop->decider = settings_.team_station;
    loop->epoch = epoch_;
    loop->loop = *msg;
    std::lock_guard<std::mutex> guard(mutex_);
    if (Peer* p = peer(pending.peer)) {
      loop->seq = ledger_.nextLoopFor(pending.peer);
      ++p->loops_decided;
      if (pending.late) ++p->loops_found_late;
      p->unacknowledged.push_back({loop, Clock::now()});
      sendTo(p->to_loops, *loop);
      p->bytes_out += bytesOf(*loop);
    }
  }
  persist();
  publish_(robots, msg);
}

// A peer's loop for one of this station's keyframes is published only as this station stored and
// heard it: its query a keyframe stored here for that robot (id and session), its candidates
// keyframes the decider announced, its content well formed (peerLoopContentProblem), and
// `accepted` decided here. A loop refused is counted; when its decider is a peer whose summaries
// this station took, its number is taken too, so that the decider's later loops are not held
// behind it (the decider resends a loop until it is counted).
void TeamLink::onLoop(const mild_lcd::TeamLoop::ConstPtr& loop) {
  const size_t robot = robotIndex(loop->loop.query_robot);
  uint64_t loops_from = 0;
  bool caught_up = false;  // every summary the decider numbered is taken here
  {
    std::lock_guard<std::mutex> guard(mutex_);
    // Only a peer's loops are taken: a name never heard from makes no peer and no ledger entry.
    const auto it = peers_.find(loop->decider);
    if (it == peers_.end() || !it->second.seen || bytesOf(*loop) > kMaxMessageBytes) {
      if (it != peers_.end()) {
        ++it->second.refused;
      } else {
        ++refused_;
      }
      ROS_WARN_STREAM_THROTTLE(10.0, "team link: a loop from '" << loop->decider.substr(0, kMaxNameLength)
                                                                << "', not a peer heard from, refused");
      return;
    }
    // The lowest it can still send, as its heartbeat says: of this loop's run only.
    loops_from = it->second.runs.current == loop->epoch ? it->second.loops_from : 0;
    caught_up = it->second.summaries <= it->second.taken;
  }
  PeerLoopRules rules;
  rules.station = settings_.team_station;
  rules.max_correspondences = static_cast<size_t>(settings_.max_keyframe_features);
  std::string problem;
  {
    const auto lock = shared_.lock();
    rules.max_candidates = static_cast<size_t>(shared_.team->params().candidates.max_candidates);
    rules.decision_probability = shared_.team->params().scoring.decision_probability;
    problem = peerLoopContentProblem(*loop, rules);
    if (problem.empty()) problem = unknownKeyframeOf(*loop, robot);
    // A candidate not announced yet, while the decider's summaries are still coming (both stored
    // at once, or a gap being filled): it is resent until its summary is taken here.
    if (!problem.empty() && problem.rfind(kNotAnnounced, 0) == 0 && !caught_up) return;
    // A decider none of whose summaries was taken cannot have decided a loop (its candidates are
    // its keyframes): nothing of it goes into the ledger.
    bool in_turn = false;  // the next of its loops expected here
    bool copy = false;     // one taken already (a resend crossing the acknowledgement)
    if (ledger_.received(loop->decider) > 0) {
      // Numbered per run of the decider: a new run's from 0; a run it left sends no more.
      if (ledger_.loopRun(loop->decider, loop->epoch) == mild::PeerRuns::Seen::kPast) return;
      // In their order only: a later one is dropped and comes again (the decider resends until
      // acknowledged), an earlier one was published already. A decider that can no longer send the
      // next one expected (it restarted, or crashed, with loops unacknowledged) is followed: those
      // loops are lost, and counted.
      uint64_t expected = ledger_.loopsReceivedFrom(loop->decider);
      const uint64_t resumes = std::min(loops_from, loop->seq);
      if (resumes > expected) {
        {
          std::lock_guard<std::mutex> guard(mutex_);
          // (loops_from is below kAbsurdCount: onStatus refuses more.)
          if (Peer* p = peer(loop->decider)) p->loops_lost += resumes - expected;
        }
        ledger_.skipLoopsReceivedTo(loop->decider, resumes);
        expected = resumes;
      }
      in_turn = loop->seq == expected;
      copy = loop->seq < expected;
      if (in_turn) ledger_.tookLoop(loop->decider);
    } else if (problem.empty()) {
      problem = kNotAnnounced;
    }
    if (!problem.empty()) {
      if (copy) return;
      std::lock_guard<std::mutex> guard(mutex_);
      if (Peer* p = peer(loop->decider)) ++p->refused;
      ROS_WARN_STREAM_THROTTLE(10.0, "team link: a loop from '" << loop->decider << "' refused: " << problem);
      return;
    }
    if (!in_turn) return;
    // Held by content: a loop its decider decided again (after its crash) is taken, not published.
    if (!ledger_.keepLoop(heldAs(loop->loop, loop->decider))) {
      std::lock_guard<std::mutex> guard(mutex_);
      if (Peer* p = peer(loop->decider)) ++p->duplicates;
      return;
    }
  }
  persist();
  publish_({robot}, peerLoopAsPublished(*loop, rules));
}

// Under the detector lock: "" when the loop's query is a keyframe this station stored for that
// robot (as the decider names it: id and session) and each candidate one the decider announced;
// else why not.
std::string TeamLink::unknownKeyframeOf(const mild_lcd::TeamLoop& loop, size_t robot) const {
  const mild_lcd::LoopClosure& l = loop.loop;
  if (robot >= robot_names_.size()) return "no robot '" + l.query_robot.substr(0, kMaxNameLength) + "' here";
  const mild::KeyframeMap& map = shared_.robot(robot).map();
  const auto index = map.find(l.query_id);
  if (!index || map.record(*index).session != l.query_session) {
    return "its query, keyframe " + std::to_string(l.query_id) + " of session " + std::to_string(l.query_session) +
           ", is not in " + l.query_robot + "'s map";
  }
  for (const auto& c : l.candidates) {
    if (!ledger_.wasAnnounced(loop.decider, c.robot, c.session, c.id)) {
      return std::string(kNotAnnounced) + ": keyframe " + std::to_string(c.id) + " of session " +
             std::to_string(c.session) + " of its robot '" + c.robot.substr(0, kMaxNameLength) + "'";
    }
  }
  return "";
}

size_t TeamLink::robotIndex(const std::string& name) const {
  return static_cast<size_t>(std::find(robot_names_.begin(), robot_names_.end(), name) - robot_names_.begin());
}

void TeamLink::serve(const mild_lcd::TeamRequest::ConstPtr& request) {
  {
    std::lock_guard<std::mutex> guard(mutex_);
    Peer* p = peer(request->from);
    if (!p) {
      ++refused_;
      return;
    }
    const auto now = Clock::now();
    const double rate = settings_.team_max_requests_per_second;
    p->tokens = std::min(2.0 * rate, p->tokens + rate * std::chrono::duration<double>(now - p->refilled).count());
    p->refilled = now;
    if (p->tokens < 1.0) {
      ++p->refused;
      if (request->kind == mild_lcd::TeamRequest::FEATURES) {
        mild_lcd::TeamFeatures busy;
        busy.from = settings_.team_station;
        busy.request_id = request->request_id;
        busy.status = mild_lcd::TeamFeatures::BUSY;
        busy.reason = "more than ~team/max_requests_per_second requests";
        sendTo(p->to_features, busy);
      }
      return;
    }
    p->tokens -= 1.0;
  }
  if (request->kind == mild_lcd::TeamRequest::SUMMARIES) {
    std::vector<mild_lcd::PlaceSummary::Ptr> batch;
    {
      const auto lock = shared_.lock();
      const uint64_t end = std::min<uint64_t>(
          ledger_.ownCount(), request->first + std::min<uint64_t>(request->count, settings_.team_backfill_batch));
      for (uint64_t seq = request->first; seq < end; ++seq) batch.push_back(summaryOf(seq));
    }
    std::lock_guard<std::mutex> guard(mutex_);
    Peer* p = peer(request->from);
    for (const auto& s : batch) {
      sendTo(p->to_summaries, *s);
      p->bytes_out += bytesOf(*s);
    }
    return;
  }
  auto reply = boost::make_shared<mild_lcd::TeamFeatures>();
  reply->from = settings_.team_station;
  reply->request_id = request->request_id;
  if (request->kind != mild_lcd::TeamRequest::FEATURES) {
    reply->status = mild_lcd::TeamFeatures::MALFORMED;
    reply->reason = "unknown request kind " + std::to_string(request->kind);
  } else if (const size_t robot = robotIndex(request->robot); robot >= robot_names_.size()) {
    reply->status = mild_lcd::TeamFeatures::UNKNOWN;
    reply->reason = "no robot '" + request->robot.substr(0, kMaxNameLength) + "' at this station";
  } else {
    const auto lock = shared_.lock();
    const mild::KeyframeMap& map = shared_.robot(robot).map();
    if (const auto index = map.find(request->id)) {
      setTeamReplyFeatures(map.features(*index), descriptor_bytes_, *reply);
      reply->keyframe.id = request->id;
      reply->keyframe.has_id = true;
      reply->status = mild_lcd::TeamFeatures::OK;
    } else {
      reply->status = mild_lcd::TeamFeatures::UNKNOWN;
      reply->reason = "robot '" + request->robot + "' has no keyframe " + std::to_string(request->id);
    }
  }
  std::lock_guard<std::mutex> guard(mutex_);
  Peer* p = peer(request->from);
  if (reply->status != mild_lcd::TeamFeatures::OK) ++p->refused;
  sendTo(p->to_features, *reply);
  p->bytes_out += bytesOf(*reply);
}

void TeamLink::tick() {
  auto status = boost::make_shared<mild_lcd::TeamStatus>();
  const auto lock = shared_.lock();
  std::lock_guard<std::mutex> guard(mutex_);
  status->station = settings_.team_station;
  status->epoch = epoch_;
  status->epoch_start = ledger_.runStart();
  status->summaries = ledger_.ownCount();
  status->descriptor_bytes = static_cast<uint32_t>(descriptor_bytes_);
  const auto now = Clock::now();
  for (auto& [name, p] : peers_) {
    status->peers.push_back(name);
    status->received.push_back(ledger_.received(name));
    status->loops_received.push_back(ledger_.loopsReceivedFrom(name));
    status->loops_epoch.push_back(ledger_.loopEpoch(name));
    status->loops_from.push_back(p.unacknowledged.empty() ? ledger_.loopsSentTo(name)
                                                          : p.unacknowledged.front().loop->seq);
    status->summaries_in += p.summaries_in;
    status->summary_bytes_in += p.summary_bytes_in;
    status->features_in += p.features_in;
    status->feature_bytes_in += p.feature_bytes_in;
    status->loops_decided += p.loops_decided;
    status->loops_found_late += p.loops_found_late;
    status->refused += p.refused;
    if (!connected(p) || !p.compatible) continue;
    // Behind, and what is next is not waiting here: ask for it (again, if unanswered).
    const bool gap = p.summaries > p.taken && (p.waiting.empty() || p.waiting.begin()->first != p.taken);
    if (gap && now - p.backfill_asked >= kResendAfter) {
      mild_lcd::TeamRequest request;
      request.from = settings_.team_station;
      request.request_id = next_request_++;
      request.kind = mild_lcd::TeamRequest::SUMMARIES;
      request.first = p.taken;
      request.count = static_cast<uint32_t>(settings_.team_backfill_batch);
      sendTo(p.to_requests, request);
      p.bytes_out += bytesOf(request);
      p.backfill_asked = now;
    }
    // Loops not acknowledged are sent again, in order, a bounded number per second.
    size_t resent = 0;
    for (auto& sent : p.unacknowledged) {
      if (resent == kMaxResendsPerTick) break;
      if (now - sent.at < kResendAfter) continue;
      // A new counter and MAC: the receiver refuses a copy of the one sent before as a replay.
      mild_lcd::TeamLoop again = *sent.loop;
      sendTo(p.to_loops, again);
      p.bytes_out += bytesOf(*sent.loop);
      sent.at = now;
      ++resent;
    }
  }
  status->refused += refused_;
  for (auto& [id, pending] : pending_) {
    Peer* p = peer(pending.peer);
    if (p && connected(*p) && now - pending.asked >= kResendAfter) sendPull(id, pending);
  }
  sign(*status, status_pub_.getTopic());
  status_pub_.publish(status);
}

void TeamLink::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  uint64_t backlog_total = 0;
  size_t disconnected = 0;
  std::lock_guard<std::mutex> guard(mutex_);
  for (const auto& [name, p] : peers_) {
    const bool up = connected(p);
    if (!up) ++disconnected;
    const uint64_t backlog = p.summaries > p.taken ? p.summaries - p.taken : 0;
    backlog_total += backlog;
    stat.add(name + ": connected", up ? "yes" : "no");
    stat.add(name + ": compatible", p.compatible ? "yes" : "no (another descriptor width)");
    stat.add(name + ": backlog (summaries not yet taken)", backlog);
    stat.add(name + ": keyframes waiting for features", p.pending_pulls);
    stat.add(name + ": bytes in (summaries)", p.summary_bytes_in);
    stat.add(name + ": bytes in (features pulled)", p.feature_bytes_in);
    stat.add(name + ": bytes out", p.bytes_out);
    stat.add(name + ": loops decided", p.loops_decided);
    stat.add(name + ": loops found late after a reconnect", p.loops_found_late);
    stat.add(name + ": loops not yet acknowledged", p.unacknowledged.size());
    stat.add(name + ": its loops lost to its restart", p.loops_lost);
    stat.add(name + ": refused", p.refused);
    stat.add(name + ": reconnects", p.reconnects);
  }
  stat.add("summaries sent", summaries_out_);
  stat.add("summary bytes sent", summary_bytes_out_);
  stat.add("refused from no peer", refused_);
  stat.add("refused unread (oversized, or another type)", refused_unread_);
  stat.add("team key", key_ ? "yes: messages without its MAC, and replays, are refused"
                            : "NO: anyone who can publish on /mild_team/ can inject loops (set ~team/key_file)");
  for (const auto& [claimed, count] : unauthenticated_) {
    stat.add(
        (claimed.empty() ? std::string("(other names)") : claimed) + ": refused, no valid team key MAC or a replay",
        count);
  }
  if (disconnected > 0) {
    stat.summaryf(diagnostic_msgs::DiagnosticStatus::WARN, "%zu of %zu peers disconnected, %lu summaries behind",
                  disconnected, peers_.size(), static_cast<unsigned long>(backlog_total));
  } else {
    stat.summaryf(diagnostic_msgs::DiagnosticStatus::OK, "%zu peers connected, %lu summaries behind", peers_.size(),
                  static_cast<unsigned long>(backlog_total));
  }
}

}  // namespace mild_lcd
