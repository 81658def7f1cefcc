#include "mild_lcd/ros/input/image_decoding.hpp"

#include <string>

#include <opencv2/imgcodecs.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"

namespace mild_lcd {

namespace {

// Wraps the message buffer; checkedInputBytes has made sure that it holds height rows of step bytes.
cv::Mat wrap(const sensor_msgs::Image& msg, int type) {
  return cv::Mat(static_cast<int>(msg.height), static_cast<int>(msg.width), type, const_cast<uint8_t*>(msg.data.data()),
                 msg.step);
}

}  // namespace

DecodedImage imageFromMsg(const sensor_msgs::Image& msg, uint64_t max_pixels) {
  checkedInputBytes(msg, InputLimits{max_pixels, kDefaultMaxKeyframeFeatures});
  const EncodingLayout& layout = encodingLayout(msg.encoding);
  if (layout.type != CV_16UC1) return DecodedImage{wrap(msg, layout.type), layout.format};
  if (msg.is_bigendian) throw mild::InvalidInput("big-endian mono16 images are not supported");
  DecodedImage out;
  wrap(msg, CV_16UC1).convertTo(out.image, CV_8UC1, 1.0 / 256.0);
  return out;
}

DecodedImage imageFromMsg(const sensor_msgs::CompressedImage& msg, uint64_t max_pixels) {
  checkedInputBytes(msg, InputLimits{max_pixels, kDefaultMaxKeyframeFeatures});
  cv::Mat decoded;
  try {
    decoded = cv::imdecode(msg.data, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    decoded.release();
  }
  if (decoded.empty()) throw mild::InvalidInput("compressed image (format '" + msg.format + "') cannot be decoded");
  refuseLargerThan(static_cast<uint64_t>(decoded.cols), static_cast<uint64_t>(decoded.rows), max_pixels,
                   "decoded image");
  if (decoded.depth() == CV_16U) decoded.convertTo(decoded, CV_8U, 1.0 / 256.0);
  if (const auto format = mild::decodedPixelFormat(decoded.channels())) return DecodedImage{decoded, *format};
  throw mild::InvalidInput("compressed image has " + std::to_string(decoded.channels()) + " channels");
}

}  // namespace mild_lcd
