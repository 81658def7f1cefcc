#include <gtest/gtest.h>

#include <random>
#include <set>

#include "mild_lcd/common/stamped_set.hpp"

namespace mild {
namespace {

TEST(StampedSet, InsertSaysWhetherTheKeyIsNew) {
  StampedSet set;
  set.clear(3);
  EXPECT_TRUE(set.insert(7));
  EXPECT_TRUE(set.insert(0));  // key 0 is a key like any other, not an empty slot
  EXPECT_FALSE(set.insert(7));
  EXPECT_FALSE(set.insert(0));
  EXPECT_TRUE(set.insert(UINT64_MAX));
}

TEST(StampedSet, ClearForgetsEveryKey) {
  StampedSet set;
  set.clear(10);
  for (uint64_t k = 0; k < 10; ++k) set.insert(k);
  set.clear(10);
  for (uint64_t k = 0; k < 10; ++k) EXPECT_TRUE(set.insert(k)) << k;
}

TEST(StampedSet, AgreesWithStdSetAcrossGrowthAndManyClears) {
  std::mt19937_64 rng(3);
  StampedSet set;
  for (int round = 0; round < 300; ++round) {
    const size_t expected = 1 + rng() % (round < 150 ? 200 : 5000);  // grows past its first size
    set.clear(expected);
    std::set<uint64_t> reference;
    for (size_t i = 0; i < expected; ++i) {
      // Few distinct values, so repeats are common; and keys that collide in the low bits.
      const uint64_t key = (rng() % (expected / 2 + 1)) << 20;
      ASSERT_EQ(set.insert(key), reference.insert(key).second) << "round " << round;
    }
  }
}

}  // namespace
}  // namespace mild
