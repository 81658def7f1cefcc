#include "mild_lcd/features/descriptor.hpp"

#include <cstring>
#include <sstream>

#include "mild_lcd/common/errors.hpp"

namespace mild {

DescriptorList descriptorsFromMat(const cv::Mat& descriptors) {
  if (descriptors.empty()) return {};
  if (descriptors.dims != 2 || descriptors.type() != CV_8UC1 || descriptors.cols != kDescriptorBytes) {
    std::ostringstream msg;
    msg << "descriptor matrix must be N x " << kDescriptorBytes << " of type CV_8UC1 (256-bit ORB), got "
        << descriptors.rows << " x " << descriptors.cols << " of type " << cv::typeToString(descriptors.type());
    throw InvalidInput(msg.str());
  }
  DescriptorList out(static_cast<size_t>(descriptors.rows));
  for (int r = 0; r < descriptors.rows; ++r) {
    std::memcpy(out[r].words.data(), descriptors.ptr<uint8_t>(r), kDescriptorBytes);
  }
  return out;
}

DescriptorList descriptorsFromBytes(const uint8_t* data, size_t size, long expected_rows) {
  if (size % kDescriptorBytes != 0) {
    std::ostringstream msg;
    msg << "descriptor data must be a multiple of " << kDescriptorBytes << " bytes (256-bit ORB rows), got " << size
        << " bytes";
    throw InvalidInput(msg.str());
  }
  const size_t rows = size / kDescriptorBytes;
  if (expected_rows >= 0 && rows != static_cast<size_t>(expected_rows)) {
    std::ostringstream msg;
    msg << "descriptor data holds " << rows << " rows of " << kDescriptorBytes << " bytes but " << expected_rows
        << " keypoints were given; each keypoint needs exactly one descriptor";
    throw InvalidInput(msg.str());
  }
  DescriptorList out(rows);
  if (rows > 0) std::memcpy(out.data(), data, size);
  return out;
}

cv::Mat descriptorsToMat(const DescriptorList& descriptors) {
  cv::Mat out(static_cast<int>(descriptors.size()), kDescriptorBytes, CV_8UC1);
  for (size_t r = 0; r < descriptors.size(); ++r) {
    std::memcpy(out.ptr<uint8_t>(static_cast<int>(r)), descriptors[r].words.data(), kDescriptorBytes);
  }
  return out;
}

}  // namespace mild
