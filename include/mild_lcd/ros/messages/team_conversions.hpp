#pragma once

// The team's messages between their wire form (msg/PlaceSummary.msg, TeamStatus, TeamRequest,
// TeamFeatures, TeamLoop) and the station protocol's plain structs (team/team_messages.hpp). The
// counter and MAC are the link's (ros/team/team_link.hpp); they are left empty here.

#include <cstdint>
#include <string>
#include <vector>

#include <ros/serialization.h>

#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/PlaceSummary.h"
#include "mild_lcd/TeamFeatures.h"
#include "mild_lcd/TeamLoop.h"
#include "mild_lcd/TeamRequest.h"
#include "mild_lcd/TeamStatus.h"
#include "mild_lcd/team/place_summary.hpp"
#include "mild_lcd/team/station.hpp"
#include "mild_lcd/team/team_messages.hpp"

namespace mild_lcd {

mild::PlaceSummary summaryFromMsg(const mild_lcd::PlaceSummary& msg);
mild_lcd::PlaceSummary summaryToMsg(const mild::PlaceSummary& summary);
mild::TeamStatus statusFromMsg(const mild_lcd::TeamStatus& msg);
mild_lcd::TeamStatus statusToMsg(const mild::TeamStatus& status);
mild::TeamRequest requestFromMsg(const mild_lcd::TeamRequest& msg);
mild_lcd::TeamRequest requestToMsg(const mild::TeamRequest& request);
// A pull's answer; a received one whose keyframe cannot be read has no features.
mild::TeamFeatures featuresReplyFromMsg(const mild_lcd::TeamFeatures& msg);
mild_lcd::TeamFeatures featuresReplyToMsg(const mild::TeamFeatures& reply, int descriptor_bytes);
// A loop decided here as its query's station and this station's robots see it: the decider's
// candidates (of `station`), the query as the peer numbered it. `robot_names`: this station's.
mild_lcd::LoopClosure decidedLoopToMsg(const mild::DecidedLoop& loop, const std::string& station, bool correspondences,
                                       const std::vector<std::string>& robot_names);
mild_lcd::TeamLoop teamLoopToMsg(const mild::DecidedLoop& loop, const std::string& station, bool correspondences,
                                 const std::vector<std::string>& robot_names);
// A peer's loop as the station protocol checks it (mild::peerLoopContentProblem), carrying a copy
// of the message as it came; and that copy as published once taken, its `accepted` set as decided
// here.
mild::PeerLoop peerLoopFromMsg(const mild_lcd::TeamLoop& msg);
mild_lcd::LoopClosure::ConstPtr peerLoopToPublish(mild::PeerLoop& loop);

// Who a message says sent it: what its MAC binds, and what its failures are counted against.
inline const std::string& senderOf(const mild_lcd::PlaceSummary& m) { return m.station; }
inline const std::string& senderOf(const mild_lcd::TeamStatus& m) { return m.station; }
inline const std::string& senderOf(const mild_lcd::TeamRequest& m) { return m.from; }
inline const std::string& senderOf(const mild_lcd::TeamFeatures& m) { return m.from; }
inline const std::string& senderOf(const mild_lcd::TeamLoop& m) { return m.decider; }

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

}  // namespace mild_lcd
