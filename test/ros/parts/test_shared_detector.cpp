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

// Maps change other than by a keyframe in one place (SharedDetector::mapReplaced, resetMaps): a
// load, a merge and the reset service all go through it, and whoever listens (the team link, which
// renumbers) hears of every robot whose map was replaced; `replaced` tells a pull in flight that
// its candidates were keyframes of an old map.
TEST(SharedDetectorMaps, EveryReplacementIsToldOnceThroughOnePlace) {
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(mild::DetectorParams{}, std::vector<std::string>{"a", "b", "c"}));
  std::vector<size_t> told;
  shared.on_map_replaced = [&](size_t robot) { told.push_back(robot); };
  const auto lock = shared.lock();
  shared.mapReplaced(1);
  EXPECT_EQ(told, (std::vector<size_t>{1}));
  EXPECT_EQ(shared.replaced, 1u);
  EXPECT_EQ(shared.changes, 1u);
  shared.mapReplaced(2, false);  // what a file holds: nothing to save
  EXPECT_EQ(shared.replaced, 2u);
  EXPECT_EQ(shared.changes, 1u);
  told.clear();
  shared.resetMaps();
  EXPECT_EQ(told, (std::vector<size_t>{0, 1, 2}));
  EXPECT_EQ(shared.replaced, 3u);
  EXPECT_EQ(shared.changes, 2u);
}

}  // namespace
}  // namespace mild_lcd
