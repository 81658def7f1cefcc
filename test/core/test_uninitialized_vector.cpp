// The allocator of the map's large arrays: contents survive growth across the 32 MB line (where
// blocks switch to 2 MB-aligned huge-page candidates) and back, and large blocks are aligned.
#include <gtest/gtest.h>

#include <cstdint>

#include "mild_lcd/common/uninitialized_vector.hpp"

namespace mild {
namespace {

using Allocator = DefaultInitAllocator<uint64_t>;

TEST(UninitializedVector, KeepsItsContentsWhenGrowingPastTheHugePageLineAndBack) {
  UninitializedVector<uint64_t> words;
  const size_t small = (Allocator::kHugeFrom / sizeof(uint64_t)) / 4;
  words.resize(small);
  for (size_t i = 0; i < small; ++i) words[i] = i * 2654435761u;
  const size_t large = 2 * Allocator::kHugeFrom / sizeof(uint64_t);
  words.resize(large);  // reallocates into a large block
  EXPECT_EQ(reinterpret_cast<uintptr_t>(words.data()) % Allocator::kHugePage, 0u) << "large blocks are 2 MB-aligned";
  for (size_t i = 0; i < small; ++i) ASSERT_EQ(words[i], i * 2654435761u) << i;
  words[large - 1] = 7;
  words.resize(small);
  words.shrink_to_fit();  // back to an ordinary block: both kinds are freed by the way they came
  for (size_t i = 0; i < small; ++i) ASSERT_EQ(words[i], i * 2654435761u) << i;
}

TEST(UninitializedVector, ValueConstructionStillInitialises) {
  UninitializedVector<uint64_t> words(1000, 42);  // only resize() without a value skips the fill
  for (uint64_t w : words) ASSERT_EQ(w, 42u);
  words.assign(Allocator::kHugeFrom / sizeof(uint64_t) + 1, 3);
  EXPECT_EQ(words.front(), 3u);
  EXPECT_EQ(words.back(), 3u);
}

}  // namespace
}  // namespace mild
