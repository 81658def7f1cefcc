// The array the map's descriptors and index ids live in: contents survive growth by remapping (also
// across the huge-page line, past which it is 2 MB-aligned whole huge pages), copies are deep, moves
// leave the source empty, clear() keeps the room and release() gives it back.
#include <gtest/gtest.h>

#include <cstdint>
#include <utility>

#include "mild_lcd/common/mapped_array.hpp"

namespace mild {
namespace {

uint64_t pattern(size_t i) { return i * 2654435761u + 1; }

void fill(MappedArray<uint64_t>& words, size_t from, size_t to) {
  for (size_t i = from; i < to; ++i) words[i] = pattern(i);
}

::testing::AssertionResult holdsPattern(const MappedArray<uint64_t>& words, size_t n) {
  for (size_t i = 0; i < n; ++i) {
    if (words[i] != pattern(i)) return ::testing::AssertionFailure() << "element " << i << " is " << words[i];
  }
  return ::testing::AssertionSuccess();
}

TEST(MappedArray, KeepsItsContentsAcrossGrowthPastTheHugePageLine) {
  MappedArray<uint64_t> words;
  size_t n = 1000;
  words.resize(n);
  fill(words, 0, n);
  // From 8 KB to 96 MB in steps of a quarter and jumps, each step a remap that may move the array.
  while (n < (size_t{96} << 20) / sizeof(uint64_t)) {
    const size_t grown = n + n / 4 + 4096;
    words.resize(grown);
    fill(words, n, grown);
    n = grown;
  }
  EXPECT_TRUE(holdsPattern(words, n));
  EXPECT_GE(words.capacity(), n);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(words.data()) % (size_t{2} << 20), 0u)
      << "a large array sits on huge-page boundaries";
  EXPECT_EQ(words.capacity() * sizeof(uint64_t) % (size_t{2} << 20), 0u) << "and is whole huge pages";
  words.resize(10);  // shrinking keeps the room
  EXPECT_GE(words.capacity(), n);
  EXPECT_TRUE(holdsPattern(words, 10));
}

// Without huge pages (the index's shards: many arrays of a few megabytes) an array past 2 MB is
// rounded to 4 KB pages only, and keeps its contents across growth all the same.
TEST(MappedArray, WithoutHugePagesRoundsToSmallPages) {
  MappedArray<uint64_t, false> words;
  const size_t n = ((size_t{3} << 20) + 4096) / sizeof(uint64_t);  // 3 MB and one page
  for (size_t i = 0; i < n; ++i) words.push_back(pattern(i));
  for (size_t i = 0; i < n; ++i) ASSERT_EQ(words[i], pattern(i)) << "element " << i;
  MappedArray<uint64_t, false> exact;
  exact.reserve(n);
  EXPECT_EQ(exact.capacity(), n) << "3 MB and one page, not rounded up to 4 MB";
  MappedArray<uint64_t> huge;
  huge.reserve(n);
  EXPECT_EQ(huge.capacity() * sizeof(uint64_t), size_t{4} << 20);
}

TEST(MappedArray, PushBackGrowsAndIterates) {
  MappedArray<uint32_t> ids;
  for (uint32_t i = 0; i < 100000; ++i) ids.push_back(i);
  ASSERT_EQ(ids.size(), 100000u);
  uint32_t expected = 0;
  for (uint32_t id : ids) ASSERT_EQ(id, expected++);
}

TEST(MappedArray, CopiesAreDeepAndMovesLeaveTheSourceEmpty) {
  MappedArray<uint64_t> a;
  a.resize(5000);
  fill(a, 0, 5000);
  MappedArray<uint64_t> b(a);
  b[0] = 0;
  EXPECT_EQ(a[0], pattern(0)) << "a copy has its own memory";
  EXPECT_TRUE(holdsPattern(a, 5000));
  MappedArray<uint64_t> c(std::move(a));
  EXPECT_TRUE(a.empty());
  EXPECT_EQ(a.capacity(), 0u);
  EXPECT_EQ(a.data(), nullptr);
  EXPECT_TRUE(holdsPattern(c, 5000));
  b = c;
  EXPECT_TRUE(holdsPattern(b, 5000));
  b = b;  // NOLINT: self-assignment keeps the contents
  EXPECT_TRUE(holdsPattern(b, 5000));
  a = std::move(b);
  EXPECT_TRUE(holdsPattern(a, 5000));
  EXPECT_TRUE(b.empty());
}

TEST(MappedArray, ClearKeepsTheRoomAndReleaseGivesItBack) {
  MappedArray<uint64_t> words;
  words.resize(1 << 20);
  const size_t room = words.capacity();
  words.clear();
  EXPECT_TRUE(words.empty());
  EXPECT_EQ(words.capacity(), room);
  words.release();
  EXPECT_EQ(words.capacity(), 0u);
  EXPECT_EQ(words.data(), nullptr);
  words.resize(3);  // usable again after release
  fill(words, 0, 3);
  EXPECT_TRUE(holdsPattern(words, 3));
}

}  // namespace
}  // namespace mild
