#include "mild_lcd/ros/input/input_admission.hpp"

#include <algorithm>
#include <string>

#include <ros/serialization.h>
#include <sensor_msgs/image_encodings.h>

#include "mild_lcd/common/errors.hpp"

namespace mild_lcd {
namespace enc = sensor_msgs::image_encodings;

namespace {

// Encodings handed to the core without conversion.
constexpr EncodingLayout kDirect[] = {
    {"mono8", CV_8UC1, mild::PixelFormat::kGray}, {"8UC1", CV_8UC1, mild::PixelFormat::kGray},
    {"bgr8", CV_8UC3, mild::PixelFormat::kBgr},   {"rgb8", CV_8UC3, mild::PixelFormat::kRgb},
    {"bgra8", CV_8UC4, mild::PixelFormat::kBgra}, {"rgba8", CV_8UC4, mild::PixelFormat::kRgba},
};

constexpr EncodingLayout kMono16{"mono16", CV_16UC1, mild::PixelFormat::kGray};

// What a message holds besides its payload (header, encoding, camera_info, ...) is small.
template <class Msg>
size_t checkedOverhead(const Msg& msg, size_t payload_bytes, const char* what) {
  const size_t total = ros::serialization::serializationLength(msg);
  if (total - payload_bytes > kMaxMessageOverheadBytes) {
    throw mild::InvalidInput(std::string(what) + " holds " + std::to_string(total - payload_bytes) +
                             " bytes besides its payload (header, strings, camera_info), more than " +
                             std::to_string(kMaxMessageOverheadBytes));
  }
  return total;
}

uint32_t bigEndian(const uint8_t* p, int bytes) {
  uint32_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | p[i];
  return v;
}

}  // namespace

const EncodingLayout& encodingLayout(const std::string& encoding) {
  for (const EncodingLayout& l : kDirect) {
    if (encoding == l.encoding) return l;
  }
  if (encoding == enc::MONO16 || encoding == enc::TYPE_16UC1) return kMono16;
  throw mild::InvalidInput("unsupported image encoding '" + encoding +
                           "' (accepted: mono8, mono16, bgr8, rgb8, bgra8, rgba8)");
}

void refuseLargerThan(uint64_t width, uint64_t height, uint64_t max_pixels, const char* what) {
  if (width * height > max_pixels) {
    throw mild::InvalidInput(std::string(what) + " of " + std::to_string(width) + " x " + std::to_string(height) +
                             " pixels is larger than ~max_image_pixels (" + std::to_string(max_pixels) + ")");
  }
}

std::optional<cv::Size> compressedImageSize(const std::vector<uint8_t>& data) {
  const size_t n = data.size();
  const uint8_t* d = data.data();
  static constexpr uint8_t kPng[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  if (n >= 24 && std::equal(kPng, kPng + 8, d) && std::equal(d + 12, d + 16, "IHDR")) {
    const uint32_t w = bigEndian(d + 16, 4), h = bigEndian(d + 20, 4);
    if (w > INT32_MAX || h > INT32_MAX) return cv::Size(INT32_MAX, INT32_MAX);
    return cv::Size(static_cast<int>(w), static_cast<int>(h));
  }
  if (n >= 4 && d[0] == 0xFF && d[1] == 0xD8) {  // JPEG: walk the markers to the frame header
    size_t pos = 2;
    while (pos + 4 <= n) {
      if (d[pos] != 0xFF) return std::nullopt;
      const uint8_t marker = d[pos + 1];
      if (marker == 0xFF) {  // fill byte
        ++pos;
        continue;
      }
      if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD9)) {  // no length field
        pos += 2;
        continue;
      }
      const size_t length = bigEndian(d + pos + 2, 2);
      const bool frame_header = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
      if (frame_header) {
        if (pos + 9 > n) return std::nullopt;
        return cv::Size(static_cast<int>(bigEndian(d + pos + 7, 2)), static_cast<int>(bigEndian(d + pos + 5, 2)));
      }
      if (length < 2) return std::nullopt;
      pos += 2 + length;
    }
  }
  return std::nullopt;
}

size_t checkedInputBytes(const sensor_msgs::Image& msg, const InputLimits& limits) {
  if (msg.width == 0 || msg.height == 0) {
    throw mild::InvalidInput("empty image (" + std::to_string(msg.width) + " x " + std::to_string(msg.height) + ")");
  }
  refuseLargerThan(msg.width, msg.height, limits.max_image_pixels, "image");
  if (msg.width > 1u << 15 || msg.height > 1u << 15) throw mild::InvalidInput("image larger than 32768 pixels a side");
  const EncodingLayout& layout = encodingLayout(msg.encoding);
  const uint64_t pixel_bytes = static_cast<uint64_t>(CV_ELEM_SIZE(layout.type));
  const uint64_t row_bytes = msg.width * pixel_bytes;
  if (msg.step < row_bytes) {
    throw mild::InvalidInput("image step " + std::to_string(msg.step) + " is smaller than a row of " +
                             std::to_string(msg.width) + " pixels (" + std::to_string(row_bytes) + " bytes)");
  }
  // OpenCV refuses (throws on) rows that do not start on a whole sample, e.g. an odd step in mono16.
  if (msg.step % CV_ELEM_SIZE1(layout.type) != 0) {
    throw mild::InvalidInput("image step " + std::to_string(msg.step) + " is not a multiple of the " +
                             std::to_string(CV_ELEM_SIZE1(layout.type)) + "-byte sample of " + msg.encoding);
  }
  const uint64_t declared = static_cast<uint64_t>(msg.step) * msg.height;
  if (msg.data.size() != declared) {
    throw mild::InvalidInput("image data holds " + std::to_string(msg.data.size()) + " bytes but " +
                             std::to_string(msg.height) + " rows of " + std::to_string(msg.step) +
                             " are declared (it must be exactly step x height)");
  }
  // A narrow image with a huge step is as large as a wide one.
  if (declared > limits.max_image_pixels * pixel_bytes) {
    throw mild::InvalidInput("image data of " + std::to_string(declared) + " bytes (step " + std::to_string(msg.step) +
                             ") is more than ~max_image_pixels (" + std::to_string(limits.max_image_pixels) +
                             ") pixels of " + msg.encoding + " hold");
  }
  return checkedOverhead(msg, msg.data.size(), "image");
}

size_t checkedInputBytes(const sensor_msgs::CompressedImage& msg, const InputLimits& limits) {
  if (msg.data.empty()) throw mild::InvalidInput("empty compressed image");
  const uint64_t max_bytes = kMaxCompressedBytesPerPixel * limits.max_image_pixels;
  if (msg.data.size() > max_bytes) {
    throw mild::InvalidInput("compressed image of " + std::to_string(msg.data.size()) + " bytes is larger than " +
                             std::to_string(max_bytes) + " (" + std::to_string(kMaxCompressedBytesPerPixel) +
                             " bytes per pixel of ~max_image_pixels)");
  }
  // The header's size, before a decoder allocates for it: 500 bytes may claim 20000 x 20000
  // pixels. Only formats whose header is read here are decoded at all (a TIFF or WebP decoder
  // allocates for its header's size before anything could judge it).
  const auto size = compressedImageSize(msg.data);
  if (!size) {
    throw mild::InvalidInput("compressed image (format '" + msg.format +
                             "') is not a JPEG or PNG whose header gives its size: only those are decoded");
  }
  if (size->width <= 0 || size->height <= 0) throw mild::InvalidInput("compressed image declares no pixels");
  refuseLargerThan(static_cast<uint64_t>(size->width), static_cast<uint64_t>(size->height), limits.max_image_pixels,
                   "compressed image");
  return checkedOverhead(msg, msg.data.size(), "compressed image");
}

size_t checkedInputBytes(const mild_lcd::Keyframe& msg, const InputLimits& limits) {
  const size_t n = limits.max_keyframe_features;
  if (msg.keypoints.size() > n || msg.descriptors.size() > n * mild::kMaxDescriptorBytes || msg.depths.size() > n) {
    throw mild::InvalidInput("keyframe has " + std::to_string(msg.keypoints.size()) + " keypoints, " +
                             std::to_string(msg.descriptors.size()) + " descriptor bytes and " +
                             std::to_string(msg.depths.size()) + " depths: more than ~max_keyframe_features (" +
                             std::to_string(n) + ") allows");
  }
  const size_t payload = msg.keypoints.size() * ros::serialization::serializationLength(mild_lcd::KeyPoint()) +
                         msg.descriptors.size() + msg.depths.size() * sizeof(float);
  return checkedOverhead(msg, payload, "keyframe");
}

}  // namespace mild_lcd
