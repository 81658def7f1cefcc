#include "mild_lcd/ros/team/team_link.hpp"

#include <topic_tools/shape_shifter.h>
#include <boost/make_shared.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/ros/messages/team_conversions.hpp"

namespace mild_lcd {
namespace {

std::string topic(const std::string& station, const std::string& name) { return "/mild_team/" + station + "/" + name; }

}  // namespace

TeamLink::TeamLink(ros::NodeHandle nh, const NodeSettings& settings, SharedDetector& shared,
                   std::vector<std::string> robot_names, std::string ledger_path, KeyFiles keys, PublishLoop publish)
    : nh_(std::move(nh)),
      settings_(settings),
      shared_(shared),
      ledger_path_(std::move(ledger_path)),
      key_files_(std::move(keys)),
      publish_(std::move(publish)),
      station_(settings.stationSettings(std::move(robot_names)), *this),
      // Above every counter of this station's earlier runs (a run sends far fewer than a message a
      // nanosecond), so that a restart's messages are not taken for replays.
      next_counter_(static_cast<uint64_t>(
          std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
              .count())) {}

TeamLink::~TeamLink() { stop(); }

// The messages of `name` are taken as bytes (topic_tools::ShapeShifter) and deserialised only when
// of type M and at most max_bytes, and with a key only when their MAC holds: a larger one is refused
// and counted unread, so that no peer's message is multiplied in memory by deserialising it (a
// TeamStatus of 240 MB of empty names once took a station to 2.2 GB).
template <class M>
ros::Subscriber TeamLink::subscribe(const std::string& name, uint32_t queue, uint64_t max_bytes,
                                    std::function<void(const M&)> handle) {
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
        if (!msg) {
          station_.refusedUnread();
          ROS_WARN_STREAM_THROTTLE(10.0, "team link: a message of "
                                             << raw->size() << " bytes of type '" << raw->getDataType() << "' on "
                                             << name << " refused unread (at most " << max_bytes << " bytes of "
                                             << ros::message_traits::datatype<M>() << ")");
          return;
        }
        if (!station_.admit(senderOf(*msg), name, msg->counter, authentic(*msg, name))) {
          ROS_WARN_STREAM_THROTTLE(10.0, "team link: a message on " << name << " claiming to be from '"
                                                                    << senderOf(*msg).substr(0, 64)
                                                                    << "' refused: no valid team key MAC, or a replay");
          return;
        }
        handle(*msg);
      };
  ros::SubscribeOptions options;
  options.initByFullCallbackType<const topic_tools::ShapeShifter::ConstPtr&>(name, queue, take);
  options.transport_hints = ros::TransportHints().tcpNoDelay();
  options.callback_queue = &queue_;
  return nh_.subscribe(options);
}

void TeamLink::start() {
  // start() runs on the worker (after the start-up load) and stop() on the nodelet's shutdown: one
  // at a time, and nothing started once stopped (the subscribers and the thread are theirs).
  std::lock_guard<std::mutex> lifecycle(lifecycle_);
  if (stopped_) return;
  credentials_ =
      mild::TeamCredentials::fromFiles(key_files_.team, key_files_.station, key_files_.roster, settings_.team_station);
  if (!credentials_.any()) {
    ROS_WARN_STREAM(
        "team link: no team key (~team/key_file): anyone who can publish on /mild_team/ can inject "
        "loops and take this station's numbers (docs/multi_robot.md, \"The team key\")");
  }
  // A link, a FIFO or a device at the ledger's name is refused (never followed, never waited on),
  // and the link stays off rather than write over it.
  std::optional<std::string> ledger;
  if (!ledger_path_.empty() && settings_.load_on_start) ledger = mild::readLedgerFile(ledger_path_);
  station_.start(ledger, credentials_.any());
  const std::string& me = settings_.team_station;
  summaries_pub_ = nh_.advertise<mild_lcd::PlaceSummary>("/mild_team/summaries", 1000);
  status_pub_ = nh_.advertise<mild_lcd::TeamStatus>("/mild_team/status", 10);
  started_ = true;
  persist();  // the ids this run reserved (Station::start), before its first keyframe
  const uint64_t summary_bytes = mild::Station::maxSummaryBytes(static_cast<size_t>(settings_.team_summary_bytes));
  const auto summary_in = [this](bool backfill) {
    return [this, backfill](const mild_lcd::PlaceSummary& m) { station_.receive(summaryFromMsg(m), backfill); };
  };
  subscribers_.push_back(
      subscribe<mild_lcd::PlaceSummary>("/mild_team/summaries", 1000, summary_bytes, summary_in(false)));
  subscribers_.push_back(
      subscribe<mild_lcd::PlaceSummary>(topic(me, "summaries"), 1000, summary_bytes, summary_in(true)));
  subscribers_.push_back(subscribe<mild_lcd::TeamStatus>(
      "/mild_team/status", 100, mild::Station::kMaxStatusBytes, [this](const mild_lcd::TeamStatus& m) {
        station_.receive(statusFromMsg(m), ros::serialization::serializationLength(m));
      }));
  subscribers_.push_back(subscribe<mild_lcd::TeamRequest>(
      topic(me, "requests"), 1000, mild::Station::kMaxRequestBytes,
      [this](const mild_lcd::TeamRequest& m) { station_.receive(requestFromMsg(m)); }));
  subscribers_.push_back(subscribe<mild_lcd::TeamFeatures>(
      topic(me, "features"), 100, mild::Station::kMaxMessageBytes,
      [this](const mild_lcd::TeamFeatures& m) { station_.receive(featuresReplyFromMsg(m)); }));
  subscribers_.push_back(
      subscribe<mild_lcd::TeamLoop>(topic(me, "loops"), 1000, mild::Station::kMaxMessageBytes,
                                    [this](const mild_lcd::TeamLoop& m) { station_.receive(peerLoopFromMsg(m)); }));
  spinner_ = std::make_unique<ros::AsyncSpinner>(1, &queue_);
  spinner_->start();
  thread_ = std::thread([this] { run(); });
}

void TeamLink::stop() {
  std::lock_guard<std::mutex> lifecycle(lifecycle_);
  stopped_ = true;
  // Keyframes of peers waiting for their features were taken already: their loops would be lost
  // with a restart. Their answers are waited for a moment (a pull takes milliseconds on a live
  // link), and so are the acknowledgements of loops sent to connected peers.
  station_.drain();
  if (thread_.joinable() && !station_.settle(std::chrono::seconds(3))) {
    ROS_WARN_STREAM("team link: stopping with " << station_.pendingPulls()
                                                << " peer keyframes still waiting for their features: their loops, "
                                                   "if any, are not found");
  }
  for (ros::Subscriber& s : subscribers_) s.shutdown();
  if (spinner_) spinner_->stop();
  station_.halt();
  if (thread_.joinable()) thread_.join();
}

void TeamLink::save() {
  if (!ledger_path_.empty() && started_) mild::writeLedgerFile(ledger_path_, station_.ledgerText());
}

void TeamLink::persist() {
  if (!settings_.save_on_shutdown) return;
  try {
    save();
  } catch (const std::exception& e) {
    ROS_WARN_STREAM_THROTTLE(10.0, "team link: could not save the station ledger: " << e.what());
  }
}

void TeamLink::stored(const mild::DetectionResult& result) {
  if (!started_) return;  // off: nothing numbered, nothing sent
  mild_lcd::PlaceSummary msg = summaryToMsg(station_.stored(result));
  sign(msg, summaries_pub_.getTopic());
  summaries_pub_.publish(msg);
  station_.sentSummary(ros::serialization::serializationLength(msg));
}

// The MAC field (TeamCredentials::seal): over the topic and the message with that field empty.
template <class M>
void TeamLink::sign(M& msg, const std::string& topic) {
  msg.counter = next_counter_++;
  msg.mac.clear();
  if (!credentials_.any()) return;
  const std::vector<uint8_t> bytes = macInput(msg, topic);
  msg.mac = credentials_.seal(bytes.data(), bytes.size());
}

template <class M>
bool TeamLink::authentic(const M& msg, const std::string& topic) const {
  if (!credentials_.any()) return true;
  const std::vector<uint8_t> bytes = macInput(msg, topic);
  return credentials_.verify(senderOf(msg), bytes.data(), bytes.size(), msg.mac);
}

// A peer's inbox before the thread advertised it (shortly after its first sight): what would go
// there is not sent, as if lost on the way; the protocol sends it again (resends, gaps, pulls).
template <class M>
void TeamLink::sendTo(const std::string& peer, const std::string& name, M msg) {
  const auto it = to_.find(peer);
  if (it == to_.end()) return;
  ros::Publisher& to = it->second.at(name);
  sign(msg, to.getTopic());
  to.publish(msg);
  station_.sent(peer, ros::serialization::serializationLength(msg));
}

void TeamLink::run() {
  while (station_.wait(std::chrono::milliseconds(100))) {
    try {
      for (const std::string& name : station_.newPeers()) {  // each advertise waits for the master
        auto& to = to_[name];
        to["requests"] = nh_.advertise<mild_lcd::TeamRequest>(topic(name, "requests"), 1000);
        to["summaries"] = nh_.advertise<mild_lcd::PlaceSummary>(topic(name, "summaries"), 1000);
        to["features"] = nh_.advertise<mild_lcd::TeamFeatures>(topic(name, "features"), 100);
        to["loops"] = nh_.advertise<mild_lcd::TeamLoop>(topic(name, "loops"), 1000);
      }
      send(station_.work());
    } catch (const std::exception& e) {
      ROS_WARN_STREAM_THROTTLE(5.0, "team link: " << e.what());
    }
  }
}

// The ledger first (a loop decided or taken is not made again after a crash), then the loops
// published, then the messages.
void TeamLink::send(mild::Outbox out) {
  if (out.persist) persist();
  const bool correspondences = settings_.publish_correspondences;
  for (const mild::DecidedLoop& loop : out.published) {
    publish_(loop.robots, boost::make_shared<mild_lcd::LoopClosure>(decidedLoopToMsg(
                              loop, settings_.team_station, correspondences, station_.settings().robots)));
  }
  for (auto& [robot, loop] : out.taken) publish_({robot}, peerLoopToPublish(loop));
  for (const mild::DecidedLoop& loop : out.loops) {
    sendTo(loop.peer, "loops",
           teamLoopToMsg(loop, settings_.team_station, correspondences, station_.settings().robots));
  }
  for (const auto& [peer, r] : out.requests) sendTo(peer, "requests", requestToMsg(r));
  for (const auto& [peer, s] : out.summaries) sendTo(peer, "summaries", summaryToMsg(s));
  const int width = station_.descriptorBytes();  // read at start(): params() needs the detector lock
  for (const auto& [peer, f] : out.features) sendTo(peer, "features", featuresReplyToMsg(f, width));
  if (out.status) {
    mild_lcd::TeamStatus status = statusToMsg(*out.status);
    sign(status, status_pub_.getTopic());
    status_pub_.publish(status);
  }
}

void TeamLink::diagnose(diagnostic_updater::DiagnosticStatusWrapper& stat) {
  const mild::StationReport report = station_.report();
  for (const auto& [key, value] : report.values) stat.add(key, value);
  const mild::StationRoster* roster = credentials_.roster();
  stat.add("station names bound to keys", roster ? "yes: " + std::to_string(roster->size()) + " stations in the roster"
                                                 : std::string("no (set ~team/roster_dir)"));
  stat.summary(report.warn ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK,
               report.summary);
}

}  // namespace mild_lcd
