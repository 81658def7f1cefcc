#include "mild_lcd/ros/messages/message_conversions.hpp"

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>

#include <Eigen/Geometry>

#include "mild_lcd/common/errors.hpp"

namespace mild_lcd {

std::vector<cv::KeyPoint> keypointsFromMsg(const std::vector<mild_lcd::KeyPoint>& msg) {
  std::vector<cv::KeyPoint> out;
  out.reserve(msg.size());
  for (const auto& k : msg) {
    if (!std::isfinite(k.x) || !std::isfinite(k.y)) throw mild::InvalidInput("keypoint with a non-finite position");
    out.emplace_back(k.x, k.y, k.size, k.angle, k.response, k.octave);
  }
  return out;
}

std::vector<mild_lcd::KeyPoint> keypointsToMsg(const std::vector<cv::KeyPoint>& keypoints) {
  std::vector<mild_lcd::KeyPoint> out(keypoints.size());
  for (size_t i = 0; i < keypoints.size(); ++i) {
    out[i].x = keypoints[i].pt.x;
    out[i].y = keypoints[i].pt.y;
    out[i].size = keypoints[i].size;
    out[i].angle = keypoints[i].angle;
    out[i].response = keypoints[i].response;
    out[i].octave = keypoints[i].octave;
  }
  return out;
}

ros::Time stampOf(double seconds) {
  // ros::Time holds unsigned 32-bit seconds and nanoseconds; a stamp outside (a keyframe given time
  // 0, or a file from elsewhere) is clamped to its range rather than thrown at the publisher. Split
  // here, not by ros::Time(double), which throws when the nanoseconds round up past its last second.
  constexpr uint32_t kLatestSecond = std::numeric_limits<uint32_t>::max();
  const ros::Time latest(kLatestSecond, 999999999u);
  if (!(seconds > 0.0)) return ros::Time(0, 0);
  if (!(seconds < 4294967296.0)) return latest;
  double whole = 0.0;
  const double fraction = std::modf(seconds, &whole);
  const auto nanoseconds = static_cast<uint64_t>(std::llround(fraction * 1e9));
  if (nanoseconds < 1000000000u) return ros::Time(static_cast<uint32_t>(whole), static_cast<uint32_t>(nanoseconds));
  return whole >= kLatestSecond ? latest : ros::Time(static_cast<uint32_t>(whole) + 1, 0);
}

int descriptorBytesOf(uint32_t field) {
  if (field == 0) return mild::kOrbDescriptorBytes;
  if (field > static_cast<uint32_t>(mild::kMaxDescriptorBytes)) {
    throw mild::InvalidInput("descriptor_bytes " + std::to_string(field) + " is not a supported width (8..64)");
  }
  return static_cast<int>(field);
}

mild::Features featuresFromMsg(const mild_lcd::Keyframe& msg) {
  mild::Features f;
  f.declared_bytes = descriptorBytesOf(msg.descriptor_bytes);  // 0 declares ORB's 32
  f.descriptors = mild::descriptorsFromBytes(msg.descriptors.data(), msg.descriptors.size(), f.declared_bytes,
                                             static_cast<long>(msg.keypoints.size()));
  f.keypoints = keypointsFromMsg(msg.keypoints);
  f.camera = intrinsicsFromMsg(msg.camera_info);
  f.depths = msg.depths;  // their count is checked by the detector (checkCameraAndDepths)
  return f;
}

mild_lcd::Keyframe featuresToMsg(const mild::Features& features, int descriptor_bytes) {
  mild_lcd::Keyframe msg;
  msg.keypoints = keypointsToMsg(features.keypoints);
  msg.descriptor_bytes = static_cast<uint32_t>(descriptor_bytes);
  mild::appendDescriptorBytes(features.descriptors, msg.descriptors);
  if (features.camera.known()) {
    msg.camera_info.K = {
        features.camera.fx, 0.0, features.camera.cx, 0.0, features.camera.fy, features.camera.cy, 0.0, 0.0, 1.0};
  }
  msg.depths = features.depths;
  return msg;
}

mild::Features featuresFromTeamReply(const mild_lcd::TeamFeatures& reply) {
  mild::Features features = featuresFromMsg(reply.keyframe);
  const float scale = reply.detection_scale == 0.0f ? 1.0f : reply.detection_scale;
  if (!mild::detectionScaleValid(scale)) {
    throw mild::InvalidInput("a pulled keyframe's detection_scale is " + std::to_string(reply.detection_scale) +
                             "; it is 1 to " + std::to_string(static_cast<int>(mild::kMaxDetectionScale)) +
                             ", or 0 for none");
  }
  features.detection_scale = scale;
  return features;
}

void setTeamReplyFeatures(const mild::Features& stored, int descriptor_bytes, mild_lcd::TeamFeatures& reply) {
  reply.keyframe = featuresToMsg(stored, descriptor_bytes);
  reply.detection_scale = mild::boundedDetectionScale(stored.detection_scale);
}

mild::CameraIntrinsics intrinsicsFromMsg(const sensor_msgs::CameraInfo& msg) {
  const mild::CameraIntrinsics camera{msg.K[0], msg.K[4], msg.K[2], msg.K[5]};
  // Unknown when the entries read are zero, whatever the others hold: drivers without a
  // calibration commonly send K all zero but K[8] = 1.
  if (camera.fx == 0.0 && camera.fy == 0.0 && camera.cx == 0.0 && camera.cy == 0.0) return {};
  // Finite but absurd values (fx 1e12, 1e-300) would not fail loudly: every candidate would just
  // fail verification.
  const auto plausible = [](double focal) { return focal >= kMinFocalPixels && focal <= kMaxFocalPixels; };
  if (!camera.known() || !camera.wellFormed() || !plausible(camera.fx) || !plausible(camera.fy) ||
      std::abs(camera.cx) > kMaxFocalPixels || std::abs(camera.cy) > kMaxFocalPixels) {
    throw mild::InvalidInput(
        "camera_info K needs fx (K[0]) and fy (K[4]) within [1, 1e6] pixels and cx (K[2]), cy (K[5]) "
        "within +-1e6; got " +
        std::to_string(camera.fx) + ", " + std::to_string(camera.fy) + ", " + std::to_string(camera.cx) + ", " +
        std::to_string(camera.cy) + " (fx, fy, cx, cy all zero = unknown)");
  }
  return camera;
}

mild_lcd::LoopClosure loopClosureToMsg(const mild::DetectionResult& result, const std_msgs::Header& header,
                                       size_t database_size, bool correspondences,
                                       const std::vector<std::string>& robot_names) {
  const auto robotName = [&](uint32_t robot) { return robot < robot_names.size() ? robot_names[robot] : ""; };
  mild_lcd::LoopClosure msg;
  msg.header = header;
  msg.query_id = result.query_id;
  msg.query_session = result.query_session;
  msg.query_robot = robotName(result.query_robot);
  msg.features = static_cast<int32_t>(result.stats.features);
  msg.database_size = static_cast<int32_t>(database_size);
  msg.extract_ms = result.stats.extract_ms;
  msg.query_ms = result.stats.query_ms;
  msg.filter_ms = result.stats.filter_ms;
  msg.verify_ms = result.stats.verify_ms;
  msg.near_past_keyframes = static_cast<int32_t>(result.stats.near_past_keyframes);
  for (const mild::LoopCandidate& c : result.candidates) {
    mild_lcd::LoopCandidate m;
    m.id = c.id;
    m.session = c.session;
    m.robot = robotName(c.robot);
    m.stamp = stampOf(c.stamp);
    m.probability = c.probability;
    m.accepted = c.accepted;
    m.filter_probability = c.filter_probability;
    m.similarity = c.similarity;
    m.verified = c.verification.verified;
    m.inliers = c.verification.inliers;
    m.matches = c.verification.matches;
    m.inlier_ratio = c.verification.inlier_ratio;
    m.fit_skipped = c.verification.fit_skipped;
    m.coverage = c.verification.coverage;
    m.homography_share = c.verification.homography_share;
    const mild::RelativePose& pose = c.verification.pose;
    m.has_relative_pose = pose.valid;
    if (pose.valid) {
      Eigen::Matrix3d rotation;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) rotation(r, c) = pose.rotation(r, c);
      const Eigen::Quaterniond q(rotation);
      m.relative_rotation.x = q.x();
      m.relative_rotation.y = q.y();
      m.relative_rotation.z = q.z();
      m.relative_rotation.w = q.w();
      m.relative_translation.x = pose.translation[0];
      m.relative_translation.y = pose.translation[1];
      m.relative_translation.z = pose.translation[2];
      m.metric_translation = pose.metric;
      m.pose_inliers = pose.inliers;
      m.reprojection_error = pose.reprojection_error;
    } else {
      m.relative_rotation.w = 1.0;  // identity, never an invalid all-zero quaternion
    }
    if (correspondences && c.verification.verified) {
      const mild::Verification& v = c.verification;
      for (const mild::FeatureMatch& match : v.inlier_matches) {
        m.inlier_query_indices.push_back(match.query);
        m.inlier_candidate_indices.push_back(match.train);
      }
      for (size_t i = 0; i < v.inlier_query_points.size() && i < v.inlier_candidate_points.size(); ++i) {
        m.inlier_query_pixels.insert(m.inlier_query_pixels.end(),
                                     {v.inlier_query_points[i].x, v.inlier_query_points[i].y});
        m.inlier_candidate_pixels.insert(m.inlier_candidate_pixels.end(),
                                         {v.inlier_candidate_points[i].x, v.inlier_candidate_points[i].y});
      }
    }
    msg.candidates.push_back(m);
  }
  return msg;
}
}  // namespace mild_lcd
