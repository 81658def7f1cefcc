#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace mild {

// Binary descriptors of any common width: ORB and BRIEF (32 bytes), BRISK and FREAK (64), AKAZE's
// MLDB (61 bytes, 486 bits used), BRIEF-16 (16). The width is a property of each descriptor and of
// the database holding them; everything from the index layout to the file format follows it.
constexpr int kOrbDescriptorBytes = 32;
constexpr int kMinDescriptorBytes = 8;
constexpr int kMaxDescriptorBytes = 64;
constexpr int kMaxDescriptorBits = kMaxDescriptorBytes * 8;
constexpr int kMaxDescriptorWords = kMaxDescriptorBytes / 8;

constexpr int descriptorWords(int bytes) { return (bytes + 7) / 8; }

// Throws InvalidInput unless bytes is a width the package handles ([8, 64]).
void checkDescriptorBytes(int bytes);

// One binary descriptor, stored as 64-bit words in the byte order OpenCV produces: bit b of the
// descriptor is bit (b % 64) of word (b / 64) on a little-endian machine, i.e. byte k of the
// OpenCV row holds bits 8k..8k+7. Words and bits past the width are zero, so that operations on two
// descriptors of one width may read whole words. Fixed storage (the widest supported) keeps
// DescriptorList a plain vector; databases store only the bytes a descriptor has.
struct Descriptor {
  std::array<uint64_t, kMaxDescriptorWords> words{};
  uint16_t bytes = kOrbDescriptorBytes;

  Descriptor() = default;
  explicit Descriptor(int width_bytes) : bytes(static_cast<uint16_t>(width_bytes)) {}

  int bits() const { return bytes * 8; }
  int numWords() const { return descriptorWords(bytes); }
  bool bit(int b) const { return (words[b >> 6] >> (b & 63)) & 1u; }
  void flip(int b) { words[b >> 6] ^= uint64_t{1} << (b & 63); }
  bool operator==(const Descriptor& o) const { return bytes == o.bytes && words == o.words; }
  bool operator!=(const Descriptor& o) const { return !(*this == o); }
};

inline int popcount64(uint64_t x) { return __builtin_popcountll(x); }

// Hamming distance over words [0, W): a compile-time count lets the compiler unroll the loop.
template <int W>
inline int hammingWords(const uint64_t* a, const uint64_t* b) {
  int d = 0;
  for (int w = 0; w < W; ++w) d += popcount64(a[w] ^ b[w]);
  return d;
}

inline int hammingWords(const uint64_t* a, const uint64_t* b, int words) {
  switch (words) {
    case 4:
      return hammingWords<4>(a, b);
    case 8:
      return hammingWords<8>(a, b);
    default: {
      int d = 0;
      for (int w = 0; w < words; ++w) d += popcount64(a[w] ^ b[w]);
      return d;
    }
  }
}

// Both descriptors must have the same width (callers check lists once, not every pair).
inline int hammingDistance(const Descriptor& a, const Descriptor& b) {
  return hammingWords(a.words.data(), b.words.data(), a.numWords());
}

using DescriptorList = std::vector<Descriptor>;

// Throws InvalidInput, naming `what`, unless every descriptor of the list is `bytes` wide.
void checkDescriptorWidth(const DescriptorList& descriptors, int bytes, const std::string& what);

// Converts an OpenCV descriptor matrix (N rows x W columns, CV_8U, one descriptor per row; W the
// width in bytes, 8..64) into descriptors. With expected_bytes > 0 the width must be that. Throws
// InvalidInput naming the problem otherwise. An empty matrix (0 rows) yields an empty list.
DescriptorList descriptorsFromMat(const cv::Mat& descriptors, int expected_bytes = 0);

// Converts a flat byte buffer (rows of `bytes` bytes, as in a ROS message) into descriptors.
// Throws InvalidInput when the width is unsupported, the size is not a multiple of it, or the row
// count differs from expected_rows (pass a negative expected_rows to skip that check).
DescriptorList descriptorsFromBytes(const uint8_t* data, size_t size, int bytes, long expected_rows = -1);

// The inverse of descriptorsFromMat: an N x W CV_8U matrix (W the list's width; 0 x 32 when empty).
cv::Mat descriptorsToMat(const DescriptorList& descriptors);

// Appends each descriptor's `bytes` bytes to `out` (the layout of ROS messages and map files).
void appendDescriptorBytes(const DescriptorList& descriptors, std::vector<uint8_t>& out);

// A Hamming distance given per 256 bits (the parameters' unit), for descriptors of `bits` bits.
inline int scaleDistance(int per_256_bits, int bits) { return (per_256_bits * bits + 128) / 256; }

}  // namespace mild
