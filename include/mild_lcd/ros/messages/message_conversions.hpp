#pragma once

// Conversions between mild_lcd's messages and the core's types: keypoints, stamps, a Keyframe's
// features, a CameraInfo's intrinsics, and the LoopClosure answer. Every function that takes a
// message validates it and throws mild::InvalidInput with a message fit for a log line or a service
// reply; none of them touches the detector.

#include <cstdint>
#include <string>
#include <vector>

#include <sensor_msgs/CameraInfo.h>
#include <std_msgs/Header.h>
#include <opencv2/core.hpp>

#include "mild_lcd/KeyPoint.h"
#include "mild_lcd/Keyframe.h"
#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/TeamFeatures.h"
#include "mild_lcd/detector/loop_detector.hpp"

namespace mild_lcd {

// A time in seconds as a ros::Time, clamped to what ros::Time can hold.
ros::Time stampOf(double seconds);

std::vector<cv::KeyPoint> keypointsFromMsg(const std::vector<mild_lcd::KeyPoint>& msg);
std::vector<mild_lcd::KeyPoint> keypointsToMsg(const std::vector<cv::KeyPoint>& keypoints);

// A message's descriptor_bytes field as a width: 0 is 32 (ORB); over 64 throws InvalidInput.
int descriptorBytesOf(uint32_t field);

// Keypoints and descriptors of a Keyframe message (descriptor_bytes of descriptor per keypoint),
// with its optional intrinsics and depths. Throws InvalidInput when the sizes do not fit; whether
// the width is the database's is for the detector to judge.
mild::Features featuresFromMsg(const mild_lcd::Keyframe& msg);

// fx, fy, cx, cy from a CameraInfo's K; unknown when those four are zero (whatever K[8] and the
// rest hold). Throws InvalidInput for a K that is neither: a focal length outside
// [kMinFocalPixels, kMaxFocalPixels], a principal point beyond +-kMaxFocalPixels, values not finite.
constexpr double kMinFocalPixels = 1.0;
constexpr double kMaxFocalPixels = 1e6;
mild::CameraIntrinsics intrinsicsFromMsg(const sensor_msgs::CameraInfo& msg);
// A keyframe's features as a Keyframe message (no header, no id): what featuresFromMsg reads back.
mild_lcd::Keyframe featuresToMsg(const mild::Features& features, int descriptor_bytes);

// A team peer's pulled keyframe (a TeamFeatures reply that is OK): featuresFromMsg of its keyframe
// with its detection_scale, 0 (a peer that sent none) being 1. Throws InvalidInput for a scale that
// cannot be one (mild::detectionScaleValid: not a number, below 1, beyond 64), as for sizes.
mild::Features featuresFromTeamReply(const mild_lcd::TeamFeatures& reply);
// The reply's fields for a stored keyframe: its features and its detection scale.
void setTeamReplyFeatures(const mild::Features& stored, int descriptor_bytes, mild_lcd::TeamFeatures& reply);

// The answer published for one processed keyframe (candidate stamps come from the candidates).
// With `correspondences`, verified candidates carry their inlier matches. `robot_names`: the
// robots of a RobotTeam by index (query_robot, each candidate's robot); none for one robot.
mild_lcd::LoopClosure loopClosureToMsg(const mild::DetectionResult& result, const std_msgs::Header& header,
                                       size_t database_size, bool correspondences = false,
                                       const std::vector<std::string>& robot_names = {});

}  // namespace mild_lcd
