#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace mild {

constexpr int kDescriptorBits = 256;
constexpr int kDescriptorBytes = kDescriptorBits / 8;
constexpr int kDescriptorWords = kDescriptorBits / 64;

// A 256-bit binary descriptor (ORB), stored as four 64-bit words in the byte order OpenCV
// produces: bit b of the descriptor is bit (b % 64) of word (b / 64) on a little-endian machine,
// i.e. byte k of the OpenCV row holds bits 8k..8k+7.
struct Descriptor {
  std::array<uint64_t, kDescriptorWords> words{};

  bool bit(int b) const { return (words[b >> 6] >> (b & 63)) & 1u; }
  void flip(int b) { words[b >> 6] ^= uint64_t{1} << (b & 63); }
  bool operator==(const Descriptor& o) const { return words == o.words; }
  bool operator!=(const Descriptor& o) const { return !(*this == o); }
};

inline int popcount64(uint64_t x) { return __builtin_popcountll(x); }

inline int hammingDistance(const Descriptor& a, const Descriptor& b) {
  return popcount64(a.words[0] ^ b.words[0]) + popcount64(a.words[1] ^ b.words[1]) +
         popcount64(a.words[2] ^ b.words[2]) + popcount64(a.words[3] ^ b.words[3]);
}

static_assert(sizeof(Descriptor) == kDescriptorBytes, "Descriptor must be exactly 32 bytes");

using DescriptorList = std::vector<Descriptor>;

// Converts an OpenCV descriptor matrix (N rows x 32 columns, CV_8U, one descriptor per row) into
// descriptors. Throws InvalidInput naming the problem when the matrix has another width or type.
// An empty matrix (0 rows) yields an empty list.
DescriptorList descriptorsFromMat(const cv::Mat& descriptors);

// Converts a flat byte buffer (count rows of 32 bytes, as in a ROS message) into descriptors.
// Throws InvalidInput when the size is not a multiple of 32 or does not match expected_rows
// (pass a negative expected_rows to skip that check).
DescriptorList descriptorsFromBytes(const uint8_t* data, size_t size, long expected_rows = -1);

// The inverse of descriptorsFromMat: an N x 32 CV_8U matrix.
cv::Mat descriptorsToMat(const DescriptorList& descriptors);

}  // namespace mild
