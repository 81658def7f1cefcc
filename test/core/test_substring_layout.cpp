#include <gtest/gtest.h>

#include <random>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/index/substring_layout.hpp"
#include "random_descriptors.hpp"

namespace mild {
namespace {

TEST(SubstringLayout, SixteenTablesAreSixteenBitsEach) {
  SubstringLayout layout(16);
  ASSERT_EQ(layout.count(), 16);
  for (int t = 0; t < 16; ++t) {
    EXPECT_EQ(layout.length(t), 16);
    EXPECT_EQ(layout.offset(t), 16 * t);
  }
}

TEST(SubstringLayout, LengthsDifferByAtMostOneBitAndCoverEveryBitOnce) {
  for (int m = SubstringLayout::kMinSubstrings; m <= SubstringLayout::kMaxSubstrings; ++m) {
    SubstringLayout layout(m);
    int covered = 0;
    int shortest = 256, longest = 0;
    for (int t = 0; t < m; ++t) {
      EXPECT_EQ(layout.offset(t), covered) << "m=" << m;
      covered += layout.length(t);
      shortest = std::min(shortest, layout.length(t));
      longest = std::max(longest, layout.length(t));
    }
    EXPECT_EQ(covered, kDescriptorBits) << "m=" << m;
    EXPECT_LE(longest - shortest, 1) << "m=" << m;
  }
  SubstringLayout fifteen(15);  // 256 = 15 * 17 + 1
  EXPECT_EQ(fifteen.length(0), 18);
  EXPECT_EQ(fifteen.length(1), 17);
}

TEST(SubstringLayout, KeyAndMaskMatchTheBitsTheyCover) {
  std::mt19937_64 rng(7);
  for (int m : {4, 5, 7, 8, 15, 16, 24, 33, 64}) {
    SubstringLayout layout(m);
    for (int trial = 0; trial < 20; ++trial) {
      const Descriptor d = test::randomDescriptor(rng);
      for (int t = 0; t < m; ++t) {
        uint64_t expected = 0;
        for (int b = 0; b < layout.length(t); ++b) expected |= uint64_t{d.bit(layout.offset(t) + b)} << b;
        ASSERT_EQ(layout.key(d, t), expected) << "m=" << m << " t=" << t;
        for (int b = 0; b < kDescriptorBits; ++b) {
          const bool inside = b >= layout.offset(t) && b < layout.offset(t) + layout.length(t);
          ASSERT_EQ(layout.mask(t).bit(b), inside);
        }
      }
    }
  }
}

TEST(SubstringLayout, RejectsUnsupportedTableCounts) {
  EXPECT_THROW(SubstringLayout(3), InvalidInput);
  EXPECT_THROW(SubstringLayout(0), InvalidInput);
  EXPECT_THROW(SubstringLayout(65), InvalidInput);
}

}  // namespace
}  // namespace mild
