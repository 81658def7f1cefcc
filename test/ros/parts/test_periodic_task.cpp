// test_ros_parts: the periodic task behind autosave (ros/periodic_task.hpp).

#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

TEST(PeriodicTask, RunsEveryPeriodUntilDestroyed) {
  std::atomic<int> runs{0};
  {
    PeriodicTask task(std::chrono::milliseconds(10), [&] { ++runs; });
    while (runs < 3) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const int after = runs;
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(runs, after) << "no run after destruction";
}

}  // namespace
}  // namespace mild_lcd
