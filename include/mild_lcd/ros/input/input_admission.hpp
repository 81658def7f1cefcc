#pragma once

// Admission of input messages: how large one may be, judged on its sizes alone (nothing is decoded
// or allocated for it) before it is queued, and which image encodings are taken at all. Each check
// throws mild::InvalidInput with a message fit for a log line.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <opencv2/core.hpp>

#include "mild_lcd/Keyframe.h"
#include "mild_lcd/features/features.hpp"

namespace mild_lcd {

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

// Width and height from a PNG's IHDR or a JPEG's frame header, without decoding; nullopt when the
// bytes are neither (or the header cannot be found).
std::optional<cv::Size> compressedImageSize(const std::vector<uint8_t>& data);
// An accepted image encoding: its OpenCV type and the channel order the core is told.
struct EncodingLayout {
  const char* encoding;
  int type;
  mild::PixelFormat format;
};
// The layout of an accepted encoding (mono8, mono16, bgr8, rgb8, bgra8, rgba8); InvalidInput for
// any other.
const EncodingLayout& encodingLayout(const std::string& encoding);
// InvalidInput naming `what` when width x height is over max_pixels (~max_image_pixels).
void refuseLargerThan(uint64_t width, uint64_t height, uint64_t max_pixels, const char* what);

}  // namespace mild_lcd
