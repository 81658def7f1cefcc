#pragma once

// Decoding of admitted image messages into images the core takes (input_admission.hpp judged their
// sizes first; decoding judges them again, so that it is safe on its own).

#include <cstdint>

#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <opencv2/core.hpp>

#include "mild_lcd/features/features.hpp"
#include "mild_lcd/ros/input/input_admission.hpp"

namespace mild_lcd {

// An image ready for the core: 8 bits per channel and its channel order.
struct DecodedImage {
  cv::Mat image;
  mild::PixelFormat format = mild::PixelFormat::kGray;
};

// mono8, bgr8, rgb8, bgra8 and rgba8 are used as they are (no copy); mono16 is scaled to mono8.
// Anything else, an empty image, or one over the bounds of checkedInputBytes is rejected.
DecodedImage imageFromMsg(const sensor_msgs::Image& msg, uint64_t max_pixels = kDefaultMaxImagePixels);
// JPEG or PNG bytes of the `compressed` transport, within the bounds of checkedInputBytes (the size
// in the file's header among them) before anything is decoded; other formats are refused.
DecodedImage imageFromMsg(const sensor_msgs::CompressedImage& msg, uint64_t max_pixels = kDefaultMaxImagePixels);
}  // namespace mild_lcd
