#include "mild_lcd/ros/messages/team_conversions.hpp"

#include <cmath>

#include <ros/serialization.h>
#include <boost/make_shared.hpp>

#include "mild_lcd/ros/messages/message_conversions.hpp"

namespace mild_lcd {

mild::PlaceSummary summaryFromMsg(const mild_lcd::PlaceSummary& msg) {
  mild::PlaceSummary s;
  s.station = msg.station;
  s.seq = msg.seq;
  s.epoch = msg.epoch;
  s.epoch_start = msg.epoch_start;
  s.robot = msg.robot;
  s.id = msg.id;
  s.session = msg.session;
  s.stamp = msg.stamp.toSec();
  s.features = msg.features;
  s.descriptor_bytes = msg.descriptor_bytes;
  s.descriptor_data = msg.descriptors;
  s.well_formed = msg.known_stations.size() == msg.known_counts.size();
  for (size_t i = 0; i < msg.known_stations.size() && i < msg.known_counts.size(); ++i) {
    s.known.emplace_back(msg.known_stations[i], msg.known_counts[i]);
  }
  s.unreachable = msg.unreachable;
  s.looped_by = msg.looped_by;
  s.wire_bytes = ros::serialization::serializationLength(msg);
  return s;
}

mild_lcd::PlaceSummary summaryToMsg(const mild::PlaceSummary& s) {
  mild_lcd::PlaceSummary msg;
  msg.station = s.station;
  msg.seq = s.seq;
  msg.epoch = s.epoch;
  msg.epoch_start = s.epoch_start;
  msg.robot = s.robot;
  msg.id = s.id;
  msg.session = s.session;
  msg.stamp = stampOf(s.stamp);
  msg.features = s.features;
  msg.descriptor_bytes = s.descriptor_bytes;
  msg.descriptors = s.descriptor_data;
  for (const auto& [station, count] : s.known) {
    msg.known_stations.push_back(station);
    msg.known_counts.push_back(count);
  }
  msg.unreachable = s.unreachable;
  msg.looped_by = s.looped_by;
  return msg;
}

namespace {

// The heartbeat's and the request's fields have the same names on both sides: one copy each way.
template <class To, class From>
To copyStatus(const From& from) {
  To to;
  to.station = from.station;
  to.epoch = from.epoch;
  to.epoch_start = from.epoch_start;
  to.summaries = from.summaries;
  to.descriptor_bytes = from.descriptor_bytes;
  to.peers = from.peers;
  to.received = from.received;
  to.loops_received = from.loops_received;
  to.loops_from = from.loops_from;
  to.loops_epoch = from.loops_epoch;
  to.summaries_in = from.summaries_in;
  to.summary_bytes_in = from.summary_bytes_in;
  to.features_in = from.features_in;
  to.feature_bytes_in = from.feature_bytes_in;
  to.loops_decided = from.loops_decided;
  to.loops_found_late = from.loops_found_late;
  to.refused = from.refused;
  return to;
}

template <class To, class From>
To copyRequest(const From& from) {
  To to;
  to.from = from.from;
  to.request_id = from.request_id;
  to.kind = from.kind;
  to.first = from.first;
  to.count = from.count;
  to.robot = from.robot;
  to.id = from.id;
  return to;
}

}  // namespace

mild::TeamStatus statusFromMsg(const mild_lcd::TeamStatus& from) { return copyStatus<mild::TeamStatus>(from); }
mild_lcd::TeamStatus statusToMsg(const mild::TeamStatus& from) { return copyStatus<mild_lcd::TeamStatus>(from); }
mild::TeamRequest requestFromMsg(const mild_lcd::TeamRequest& from) { return copyRequest<mild::TeamRequest>(from); }
mild_lcd::TeamRequest requestToMsg(const mild::TeamRequest& from) { return copyRequest<mild_lcd::TeamRequest>(from); }

mild::TeamFeatures featuresReplyFromMsg(const mild_lcd::TeamFeatures& msg) {
  mild::TeamFeatures reply;
  reply.from = msg.from;
  reply.request_id = msg.request_id;
  reply.status = msg.status;
  reply.wire_bytes = ros::serialization::serializationLength(msg);
  if (msg.status != mild_lcd::TeamFeatures::OK) return reply;
  try {
    reply.features = featuresFromTeamReply(msg);  // with its keypoints' precision, the detection scale
    mild::checkCameraAndDepths(*reply.features);
  } catch (const std::exception&) {
    reply.features.reset();  // unreadable: judged unverified, counted
  }
  return reply;
}

mild_lcd::TeamFeatures featuresReplyToMsg(const mild::TeamFeatures& reply, int descriptor_bytes) {
  mild_lcd::TeamFeatures msg;
  msg.from = reply.from;
  msg.request_id = reply.request_id;
  msg.status = reply.status;
  msg.reason = reply.reason;
  if (reply.features) {
    setTeamReplyFeatures(*reply.features, descriptor_bytes, msg);
    msg.keyframe.id = reply.id;
    msg.keyframe.has_id = true;
  }
  return msg;
}

mild_lcd::LoopClosure decidedLoopToMsg(const mild::DecidedLoop& loop, const std::string& station, bool correspondences,
                                       const std::vector<std::string>& robot_names) {
  std_msgs::Header header;
  header.stamp = stampOf(loop.query_stamp);
  mild_lcd::LoopClosure msg = loopClosureToMsg(loop.result, header, loop.database_size, correspondences, robot_names);
  msg.query_id = loop.query_id;
  msg.query_session = loop.query_session;  // ids repeat across sessions: the pair names it
  msg.query_robot = loop.query_robot;
  msg.query_station = loop.peer;
  msg.features = static_cast<int32_t>(loop.query_features);
  for (auto& c : msg.candidates) c.station = station;
  return msg;
}

mild_lcd::TeamLoop teamLoopToMsg(const mild::DecidedLoop& loop, const std::string& station, bool correspondences,
                                 const std::vector<std::string>& robot_names) {
  mild_lcd::TeamLoop msg;
  msg.decider = station;
  msg.epoch = loop.epoch;
  msg.seq = loop.seq;
  msg.loop = decidedLoopToMsg(loop, station, correspondences, robot_names);
  return msg;
}

mild::PeerLoop peerLoopFromMsg(const mild_lcd::TeamLoop& msg) {
  mild::PeerLoop p;
  p.decider = msg.decider;
  p.epoch = msg.epoch;
  p.seq = msg.seq;
  const mild_lcd::LoopClosure& l = msg.loop;
  p.query = {l.query_station, l.query_robot, l.query_session, l.query_id, msg.decider};
  for (const mild_lcd::LoopCandidate& c : l.candidates) {
    mild::PeerLoop::Candidate& k = p.candidates.emplace_back();
    k.station = c.station;
    k.robot = c.robot;
    k.session = c.session;
    k.id = c.id;
    k.probability = c.probability;
    k.filter_probability = c.filter_probability;
    k.similarity = c.similarity;
    k.verified = c.verified != 0;
    k.inliers = c.inliers;
    k.matches = c.matches;
    k.pose_inliers = c.pose_inliers;
    k.inlier_ratio = c.inlier_ratio;
    k.coverage = c.coverage;
    k.homography_share = c.homography_share;
    const auto& q = c.relative_rotation;
    const auto& t = c.relative_translation;
    k.pose = {q.x, q.y, q.z, q.w, t.x, t.y, t.z};
    k.reprojection_error = c.reprojection_error;
    k.query_indices = c.inlier_query_indices.size();
    k.candidate_indices = c.inlier_candidate_indices.size();
    k.query_pixels = c.inlier_query_pixels.size();
    k.candidate_pixels = c.inlier_candidate_pixels.size();
    for (const float v : c.inlier_query_pixels) k.pixels_finite = k.pixels_finite && std::isfinite(v);
    for (const float v : c.inlier_candidate_pixels) k.pixels_finite = k.pixels_finite && std::isfinite(v);
  }
  p.frame_id_bytes = l.header.frame_id.size();
  p.timings = {l.extract_ms, l.query_ms, l.filter_ms, l.verify_ms};
  p.published = boost::make_shared<mild_lcd::LoopClosure>(l);  // this PeerLoop's own copy
  p.wire_bytes = ros::serialization::serializationLength(msg);
  return p;
}

mild_lcd::LoopClosure::ConstPtr peerLoopToPublish(mild::PeerLoop& loop) {
  auto msg = std::any_cast<mild_lcd::LoopClosure::Ptr>(loop.published);
  for (size_t i = 0; i < msg->candidates.size() && i < loop.candidates.size(); ++i) {
    msg->candidates[i].accepted = loop.candidates[i].accepted;
  }
  return msg;
}

}  // namespace mild_lcd
