// test_ros_parts: retuning the shared detector without waiting for it (ros/shared_detector.hpp).

#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

// Live tuning never waits for the detector (a merge or a save may hold it for seconds; the
// dynamic_reconfigure server shares the nodelet's callback queue): a retune that finds the lock
// held waits for its holder, and is in force before anyone next reads the parameters.
TEST(SharedDetectorRetune, NeverWaitsForTheDetectorAndHoldsBeforeItIsNextUsed) {
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>()));
  mild::DetectorParams next = shared.team->params();
  ASSERT_NE(next.candidates.max_candidates, 1);
  next.candidates.max_candidates = 1;
  {
    std::unique_lock<std::mutex> merging(shared.mutex);  // someone holds the detector
    shared.requestRetune(next);                          // returns without waiting for it
    EXPECT_TRUE(shared.retunePending());
    EXPECT_NE(shared.team->params().candidates.max_candidates, 1);
  }
  {
    const auto lock = shared.lock();  // the next user: the keyframe worker, a service
    EXPECT_EQ(shared.team->params().candidates.max_candidates, 1);
  }
  EXPECT_FALSE(shared.retunePending());
  next.candidates.max_candidates = 2;
  shared.requestRetune(next);  // the detector is free: applied at once
  EXPECT_FALSE(shared.retunePending());
  EXPECT_EQ(shared.team->params().candidates.max_candidates, 2);
  EXPECT_EQ(shared.team->retunes(), 2u);
}

}  // namespace
}  // namespace mild_lcd
