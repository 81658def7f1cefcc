#pragma once

// Conversions between mild_lcd's ROS messages and the ROS-free core. Every function that takes a
// message validates it and throws mild::InvalidInput with a message fit for a log line or a service
// reply; none of them touches the detector.

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/Header.h>
#include <opencv2/core.hpp>

#include "mild_lcd/KeyPoint.h"
#include "mild_lcd/Keyframe.h"
#include "mild_lcd/LoopClosure.h"
#include "mild_lcd/SparseMatch.h"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace mild_lcd {

// An image ready for the core: 8 bits per channel and its channel order.
struct DecodedImage {
  cv::Mat image;
  mild::PixelFormat format = mild::PixelFormat::kGray;
};

constexpr uint64_t kDefaultMaxImagePixels = 4096ull * 4096ull;
constexpr size_t kDefaultMaxKeyframeFeatures = 10000;

// How large one input message may be, judged on its sizes alone (nothing is decoded or allocated
// for it) before it is queued: a client can neither fill the node's memory nor have it decode what
// it then refuses.
//   - Image: width x height <= max_image_pixels; data exactly step x height, and at most
//     max_image_pixels x bytes per pixel of its encoding (padding cannot inflate it);
//   - CompressedImage: JPEG or PNG only (the formats whose header gives the size), the header's
//     width x height <= max_image_pixels, and at most kMaxCompressedBytesPerPixel x max_image_pixels
//     bytes;
//   - Keyframe: at most max_keyframe_features keypoints (descriptors and depths to match);
//   - any: at most kMaxMessageOverheadBytes besides that payload (header, encoding, camera_info).
struct InputLimits {
  uint64_t max_image_pixels = kDefaultMaxImagePixels;
  size_t max_keyframe_features = kDefaultMaxKeyframeFeatures;
};
constexpr size_t kMaxMessageOverheadBytes = 64 * 1024;
constexpr uint64_t kMaxCompressedBytesPerPixel = 4;  // a raw bgra8 image's
// Each throws InvalidInput naming the bound a message breaks; returns its size in bytes (what it
// occupies while it waits in the queue).
size_t checkedInputBytes(const sensor_msgs::Image& msg, const InputLimits& limits);
size_t checkedInputBytes(const sensor_msgs::CompressedImage& msg, const InputLimits& limits);
size_t checkedInputBytes(const mild_lcd::Keyframe& msg, const InputLimits& limits);

// mono8, bgr8, rgb8, bgra8 and rgba8 are used as they are (no copy); mono16 is scaled to mono8.
// Anything else, an empty image, or one over the bounds of checkedInputBytes is rejected.
DecodedImage imageFromMsg(const sensor_msgs::Image& msg, uint64_t max_pixels = kDefaultMaxImagePixels);
// JPEG or PNG bytes of the `compressed` transport, within the bounds of checkedInputBytes (the size
// in the file's header among them) before anything is decoded; other formats are refused.
DecodedImage imageFromMsg(const sensor_msgs::CompressedImage& msg, uint64_t max_pixels = kDefaultMaxImagePixels);
// Width and height from a PNG's IHDR or a JPEG's frame header, without decoding; nullopt when the
// bytes are neither (or the header cannot be found).
std::optional<cv::Size> compressedImageSize(const std::vector<uint8_t>& data);
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

// The answer published for one processed keyframe (candidate stamps come from the candidates).
// With `correspondences`, verified candidates carry their inlier matches. `robot_names`: the
// robots of a RobotTeam by index (query_robot, each candidate's robot); none for one robot.
mild_lcd::LoopClosure loopClosureToMsg(const mild::DetectionResult& result, const std_msgs::Header& header,
                                       size_t database_size, bool correspondences = false,
                                       const std::vector<std::string>& robot_names = {});

// Serves a SparseMatch request. `stored` returns a copy of the features of a keyframe in the
// database (none for an unknown id), so that the matching itself needs no lock on it. A side with
// more than max_features descriptors, given in the request or stored, is refused. Failures come back as success = false
// with a message, never as exceptions.
using StoredFeatures = std::function<std::optional<mild::Features>(uint64_t id)>;
constexpr size_t kDefaultMaxMatchFeatures = 10000;
mild_lcd::SparseMatch::Response sparseMatch(const mild_lcd::SparseMatch::Request& request, const StoredFeatures& stored,
                                            const mild::GeometricVerifier& verifier,
                                            size_t max_features = kDefaultMaxMatchFeatures);

}  // namespace mild_lcd
