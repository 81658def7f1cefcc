#include "mild_lcd/features/descriptor.hpp"

#include <cstring>
#include <sstream>

#include "mild_lcd/common/errors.hpp"

namespace mild {

void checkDescriptorBytes(int bytes) {
  if (bytes < kMinDescriptorBytes || bytes > kMaxDescriptorBytes) {
    throw InvalidInput("descriptors of " + std::to_string(bytes) + " bytes are not supported (binary descriptors of " +
                       std::to_string(kMinDescriptorBytes) + " to " + std::to_string(kMaxDescriptorBytes) +
                       " bytes: ORB/BRIEF 32, AKAZE 61, BRISK/FREAK 64)");
  }
}

void checkDescriptorWidth(const DescriptorList& descriptors, int bytes, const std::string& what) {
  for (const Descriptor& d : descriptors) {
    if (d.bytes != bytes) {
      throw InvalidInput(what + " has descriptors of " + std::to_string(d.bytes) + " bytes where " +
                         std::to_string(bytes) + "-byte ones are expected");
    }
  }
}

namespace {

Descriptor fromRow(const uint8_t* row, int bytes) {
  Descriptor d(bytes);
  std::memcpy(d.words.data(), row, static_cast<size_t>(bytes));
  return d;
}

}  // namespace

DescriptorList descriptorsFromMat(const cv::Mat& descriptors, int expected_bytes) {
  if (descriptors.empty()) return {};
  if (descriptors.dims != 2 || descriptors.type() != CV_8UC1 || descriptors.cols < kMinDescriptorBytes ||
      descriptors.cols > kMaxDescriptorBytes || (expected_bytes > 0 && descriptors.cols != expected_bytes)) {
    std::ostringstream msg;
    msg << "descriptor matrix must be N x ";
    if (expected_bytes > 0)
      msg << expected_bytes;
    else
      msg << "W (W = " << kMinDescriptorBytes << ".." << kMaxDescriptorBytes << " bytes)";
    msg << " of type CV_8UC1, got " << descriptors.rows << " x " << descriptors.cols << " of type "
        << cv::typeToString(descriptors.type());
    throw InvalidInput(msg.str());
  }
  DescriptorList out;
  out.reserve(static_cast<size_t>(descriptors.rows));
  for (int r = 0; r < descriptors.rows; ++r) out.push_back(fromRow(descriptors.ptr<uint8_t>(r), descriptors.cols));
  return out;
}

DescriptorList descriptorsFromBytes(const uint8_t* data, size_t size, int bytes, long expected_rows) {
  checkDescriptorBytes(bytes);
  const size_t width = static_cast<size_t>(bytes);
  if (size % width != 0) {
    std::ostringstream msg;
    msg << "descriptor data must be a multiple of " << bytes << " bytes (one row per keypoint), got " << size
        << " bytes";
    throw InvalidInput(msg.str());
  }
  const size_t rows = size / width;
  if (expected_rows >= 0 && rows != static_cast<size_t>(expected_rows)) {
    std::ostringstream msg;
    msg << "descriptor data holds " << rows << " rows of " << bytes << " bytes but " << expected_rows
        << " keypoints were given; each keypoint needs exactly one descriptor";
    throw InvalidInput(msg.str());
  }
  DescriptorList out;
  out.reserve(rows);
  for (size_t r = 0; r < rows; ++r) out.push_back(fromRow(data + r * width, bytes));
  return out;
}

cv::Mat descriptorsToMat(const DescriptorList& descriptors) {
  const int bytes = descriptors.empty() ? kOrbDescriptorBytes : descriptors.front().bytes;
  cv::Mat out(static_cast<int>(descriptors.size()), bytes, CV_8UC1);
  for (size_t r = 0; r < descriptors.size(); ++r) {
    std::memcpy(out.ptr<uint8_t>(static_cast<int>(r)), descriptors[r].words.data(), static_cast<size_t>(bytes));
  }
  return out;
}

void appendDescriptorBytes(const DescriptorList& descriptors, std::vector<uint8_t>& out) {
  for (const Descriptor& d : descriptors) {
    const auto* bytes = reinterpret_cast<const uint8_t*>(d.words.data());
    out.insert(out.end(), bytes, bytes + d.bytes);
  }
}

}  // namespace mild
