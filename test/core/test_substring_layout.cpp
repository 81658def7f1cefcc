#include <gtest/gtest.h>

#include <random>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/index/substring_layout.hpp"
#include "random_descriptors.hpp"

namespace mild {
namespace {

TEST(SubstringLayout, SixteenTablesAreSixteenBitsEach) {
  SubstringLayout layout(16, 256);
  ASSERT_EQ(layout.count(), 16);
  for (int t = 0; t < 16; ++t) {
    EXPECT_EQ(layout.length(t), 16);
    EXPECT_EQ(layout.offset(t), 16 * t);
  }
}

TEST(SubstringLayout, LengthsDifferByAtMostOneBitAndCoverEveryBitOnce) {
  for (int bits : {128, 256, 488, 512}) {
    for (int m = std::max(SubstringLayout::kMinSubstrings, SubstringLayout::substringsFor(bits, 64));
         m <= SubstringLayout::kMaxSubstrings; ++m) {
      SubstringLayout layout(m, bits);
      int covered = 0;
      int shortest = bits, longest = 0;
      for (int t = 0; t < m; ++t) {
        EXPECT_EQ(layout.offset(t), covered) << "m=" << m;
        covered += layout.length(t);
        shortest = std::min(shortest, layout.length(t));
        longest = std::max(longest, layout.length(t));
      }
      EXPECT_EQ(covered, bits) << "m=" << m;
      EXPECT_LE(longest - shortest, 1) << "m=" << m;
      EXPECT_LE(longest, 64) << "m=" << m;
    }
  }
  SubstringLayout fifteen(15, 256);  // 256 = 15 * 17 + 1
  EXPECT_EQ(fifteen.length(0), 18);
  EXPECT_EQ(fifteen.length(1), 17);
}

TEST(SubstringLayout, KeyAndMaskMatchTheBitsTheyCover) {
  std::mt19937_64 rng(7);
  for (auto [bits, m] : std::vector<std::pair<int, int>>{{256, 4},
                                                         {256, 5},
                                                         {256, 7},
                                                         {256, 15},
                                                         {256, 16},
                                                         {256, 33},
                                                         {256, 64},
                                                         {512, 8},
                                                         {512, 32},
                                                         {488, 31},
                                                         {488, 9},
                                                         {128, 6}}) {
    SubstringLayout layout(m, bits);
    for (int trial = 0; trial < 20; ++trial) {
      const Descriptor d = test::randomDescriptor(rng, bits / 8);
      for (int t = 0; t < m; ++t) {
        uint64_t expected = 0;
        for (int b = 0; b < layout.length(t); ++b) expected |= uint64_t{d.bit(layout.offset(t) + b)} << b;
        ASSERT_EQ(layout.key(d, t), expected) << "bits=" << bits << " m=" << m << " t=" << t;
        for (int b = 0; b < kMaxDescriptorBits; ++b) {
          const bool inside = b >= layout.offset(t) && b < layout.offset(t) + layout.length(t);
          ASSERT_EQ(layout.mask(t).bit(b), inside);
        }
      }
    }
  }
}

TEST(SubstringLayout, ProbeMasksAreEveryFlipWithinTheRadius) {
  const SubstringLayout layout(15, 256);  // lengths 18 and 17
  const auto masks = layout.probeMasks(2);
  ASSERT_EQ(masks.size(), 19u);
  EXPECT_EQ(masks[18].size(), 1u + 18u + 18u * 17u / 2u);
  EXPECT_EQ(masks[17].size(), 1u + 17u + 17u * 16u / 2u);
  for (uint64_t m : masks[17]) EXPECT_LE(__builtin_popcountll(m), 2);
  EXPECT_TRUE(masks[16].empty());  // no substring of that length
}

TEST(SubstringLayout, RejectsUnsupportedTableCountsAndWidths) {
  EXPECT_THROW(SubstringLayout(3, 256), InvalidInput);
  EXPECT_THROW(SubstringLayout(0, 256), InvalidInput);
  EXPECT_THROW(SubstringLayout(65, 256), InvalidInput);
  EXPECT_THROW(SubstringLayout(7, 512), InvalidInput);  // 74-bit substrings
  EXPECT_THROW(SubstringLayout(16, 1024), InvalidInput);
  EXPECT_THROW(SubstringLayout(16, 250), InvalidInput);  // not whole bytes
}

}  // namespace
}  // namespace mild
