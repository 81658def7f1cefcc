#include <gtest/gtest.h>

#include <atomic>
#include <thread>
#include <vector>

#include "mild_lcd/ros/detection/bounded_queue.hpp"

namespace mild {
namespace {

TEST(BoundedQueue, KeepsOrderAndDropsTheOldestWhenFull) {
  BoundedQueue<int> q(3);
  EXPECT_TRUE(q.push(1));
  EXPECT_TRUE(q.push(2));
  EXPECT_TRUE(q.push(3));
  EXPECT_FALSE(q.push(4));  // 1 is dropped
  EXPECT_EQ(q.dropped(), 1u);
  EXPECT_EQ(q.size(), 3u);
  EXPECT_EQ(*q.pop(), 2);
  EXPECT_EQ(*q.pop(), 3);
  EXPECT_EQ(*q.pop(), 4);
}

TEST(BoundedQueue, CloseWakesTheWorkerAndDiscardsLaterPushes) {
  BoundedQueue<int> q(2);
  std::thread worker([&] { EXPECT_FALSE(q.pop().has_value()); });
  q.close();
  worker.join();
  EXPECT_FALSE(q.push(7));
  EXPECT_EQ(q.dropped(), 1u);
}

TEST(BoundedQueue, DrainsEverythingPushedFromManyThreadsWithoutLoss) {
  BoundedQueue<int> q(100000);
  std::atomic<long> sum{0};
  std::atomic<int> count{0};
  std::thread worker([&] {
    while (auto item = q.pop()) {
      sum += *item;
      ++count;
      q.done();
    }
  });
  std::vector<std::thread> producers;
  for (int p = 0; p < 4; ++p) {
    producers.emplace_back([&, p] {
      for (int i = 0; i < 5000; ++i) q.push(p * 5000 + i);
    });
  }
  for (auto& t : producers) t.join();
  q.waitIdle();
  EXPECT_EQ(count.load(), 20000);
  EXPECT_EQ(sum.load(), 20000L * 19999 / 2);
  EXPECT_EQ(q.dropped(), 0u);
  q.close();
  worker.join();
}

TEST(BoundedQueue, CountsEveryDropUnderPressure) {
  BoundedQueue<int> q(8);
  std::atomic<int> processed{0};
  std::thread worker([&] {
    while (auto item = q.pop()) {
      std::this_thread::sleep_for(std::chrono::microseconds(50));
      ++processed;
      q.done();
    }
  });
  for (int i = 0; i < 2000; ++i) q.push(i);
  q.waitIdle();
  EXPECT_EQ(processed.load() + static_cast<int>(q.dropped()), 2000);
  EXPECT_GT(q.dropped(), 0u);
  q.close();
  worker.join();
}

TEST(BoundedQueue, ClearEmptiesWithoutCountingDrops) {
  BoundedQueue<int> q(5);
  q.push(1);
  q.push(2);
  EXPECT_EQ(q.clear(), 2u);
  EXPECT_EQ(q.size(), 0u);
  EXPECT_EQ(q.dropped(), 0u);
}

// Bounded in bytes as well as items: a few large items push out older ones until the new one fits.
TEST(BoundedQueue, IsBoundedInBytesToo) {
  BoundedQueue<int> q(100, 1000);
  EXPECT_TRUE(q.push(1, 400));
  EXPECT_TRUE(q.push(2, 400));
  EXPECT_EQ(q.bytes(), 800u);
  EXPECT_FALSE(q.push(3, 400)) << "1 goes to make room";
  EXPECT_EQ(q.dropped(), 1u);
  EXPECT_EQ(q.bytes(), 800u);
  EXPECT_FALSE(q.push(4, 1000)) << "2 and 3 go";
  EXPECT_EQ(q.dropped(), 3u);
  EXPECT_EQ(q.size(), 1u);
  EXPECT_EQ(*q.pop(), 4);
  q.done();
  EXPECT_EQ(q.bytes(), 0u);
  EXPECT_TRUE(q.push(5, 10));
  EXPECT_TRUE(q.push(6, 10));
  EXPECT_EQ(q.clear(), 2u);
  EXPECT_EQ(q.bytes(), 0u);
}

}  // namespace
}  // namespace mild
