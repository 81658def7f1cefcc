// test_ros_parts: the keyframe worker (ros/keyframe_worker.hpp): counting, its queue's bounds, its two stages.

#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

TEST(Worker, CountsEveryKeyframeAnsweredRejectedOrDiscarded) {
  SharedDetector shared;
  mild::DetectorParams p;
  p.verification.enabled = false;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(p)));
  std::atomic<int> published{0};
  KeyframeWorker::Hooks hooks;
  hooks.publish = [&](const ProcessedKeyframe&) {
    ++published;
    throw std::runtime_error("a publisher that fails");  // not the keyframe's fault
  };
  KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{1000 * 1000, 10000}, hooks);
  worker.start();
  worker.push(imageInput(image(200, 150, 1.0)));
  worker.push(imageInput(image(1, 1, 2.0)));           // thinner than ORB's border: stored, no features
  worker.push(imageInput(image(8, 8, 3.0, "32FC1")));  // unusable encoding
  worker.push(imageInput(image(2000, 1000, 4.0)));     // over max_image_pixels
  worker.waitIdle();
  const WorkerCounters c = worker.counters();
  EXPECT_EQ(c.processed, 2u) << "the thin image is a keyframe, answered";
  EXPECT_EQ(c.rejected, 2u);
  EXPECT_EQ(published.load(), 2);
  EXPECT_EQ(shared.robot(0).map().size(), 2u);
}

// Issue 49 item 4: depths out of range are unknown, counted and said; the keyframe is answered.
TEST(Worker, CountsAndSaysDepthsOutOfRange) {
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>()));
  Answers answers;
  KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{1000 * 1000, 10000}, recordingHooks(answers));
  worker.start();
  auto absurd = keyframeMsg(1.0, std::nullopt);
  absurd->depths = {1e30f, 1e-30f, std::numeric_limits<float>::quiet_NaN()};  // the NaN: unknown, not absurd
  worker.push(keyframeInput(absurd));
  auto plausible = keyframeMsg(2.0, std::nullopt);
  plausible->depths = {0.5f, 0.0f, 20.0f};
  worker.push(keyframeInput(plausible));
  worker.waitIdle();
  const WorkerCounters c = worker.counters();
  EXPECT_EQ(c.processed, 2u);
  EXPECT_EQ(c.depths_out_of_range, 2u);
  std::lock_guard<std::mutex> lock(answers.mutex);
  ASSERT_EQ(answers.events.size(), 3u);
  EXPECT_NE(answers.events[0].find("2 depths outside"), std::string::npos) << answers.events[0];
}

// Issue 49 item 3: a stamp below the previous keyframe's is counted and said; the keyframe answered.
TEST(Worker, CountsAndSaysAClockThatStepsBack) {
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>()));
  Answers answers;
  KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{1000 * 1000, 10000}, recordingHooks(answers));
  worker.start();
  for (const double stamp : {2000.0, 2001.0, 5.0, 6.0, 6.0})
    worker.push(keyframeInput(keyframeMsg(stamp, std::nullopt)));
  worker.waitIdle();
  const WorkerCounters c = worker.counters();
  EXPECT_EQ(c.processed, 5u);
  EXPECT_EQ(c.clock_steps_back, 1u) << "one step back; an equal stamp is none";
  std::lock_guard<std::mutex> lock(answers.mutex);
  ASSERT_EQ(answers.events.size(), 6u);
  EXPECT_NE(answers.events[2].find("stepped back"), std::string::npos) << answers.events[2];
}

TEST(Worker, StoppingDiscardsWhatWaitsAndCountsIt) {
  for (const bool extraction_thread : {false, true}) {
    SCOPED_TRACE(extraction_thread ? "extraction thread" : "one thread");
    SharedDetector shared;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>()));
    std::mutex gate;
    std::unique_lock<std::mutex> hold(gate);  // the first keyframe waits here until we let it go
    std::atomic<bool> publishing{false};
    KeyframeWorker::Hooks hooks;
    hooks.publish = [&](const ProcessedKeyframe&) {
      publishing = true;
      std::lock_guard<std::mutex> wait(gate);
    };
    KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{1000 * 1000, 10000}, hooks, extraction_thread);
    worker.start();
    for (int i = 0; i < 10; ++i) worker.push(imageInput(image(160, 120, i)));
    EXPECT_TRUE(eventually([&] { return publishing.load(); }));
    std::thread stopper([&] { worker.stop(); });
    EXPECT_TRUE(eventually([&] { return worker.counters().discarded > 0; }));
    hold.unlock();
    stopper.join();
    const WorkerCounters c = worker.counters();
    EXPECT_EQ(c.processed + c.discarded + c.dropped + c.rejected, 10u) << "every keyframe accounted for";
    EXPECT_EQ(c.processed, 1u);
  }
}

// Oversize messages are rejected (counted) as they are pushed, so they are released at once; the
// queue holds at most queue_bytes of messages, dropping (counting) the oldest to make room.
// With the extraction thread, one keyframe more is out of the queue: extracted, waiting for the
// detector (the hand-off), where no drop reaches it.
TEST(Worker, TheQueueIsBoundedInBytesAndOversizeInputsAreRejectedAsTheyArrive) {
  for (const bool extraction_thread : {false, true}) {
    SCOPED_TRACE(extraction_thread ? "extraction thread" : "one thread");
    SharedDetector shared;
    mild::DetectorParams p;
    p.verification.enabled = false;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(p)));
    std::mutex gate;
    std::unique_lock<std::mutex> hold(gate);  // the worker waits in its first publish until released
    std::atomic<int> staged{0};
    KeyframeWorker::Hooks hooks;
    hooks.publish = [&](const ProcessedKeyframe&) { std::lock_guard<std::mutex> wait(gate); };
    hooks.staged = [&](const std_msgs::Header&, bool) { ++staged; };
    KeyframeWorker worker(shared, 100, 200 * 1000, InputLimits{2000 * 2000, 10000}, hooks, extraction_thread);
    worker.start();
    EXPECT_EQ(worker.push(imageInput(image(200, 150, 1.0))), KeyframeWorker::Pushed::kQueued);
    while (worker.counters().queued > 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));  // in progress
    auto oversize = image(320, 240, 2.0);
    oversize->data.resize(oversize->data.size() * 2);
    EXPECT_EQ(worker.push(imageInput(oversize)), KeyframeWorker::Pushed::kRejected);
    EXPECT_EQ(oversize.use_count(), 1) << "not kept by the worker";
    EXPECT_EQ(worker.push(imageInput(image(500, 500, 3.0))), KeyframeWorker::Pushed::kRejected)
        << "larger than the whole queue";
    for (int i = 0; i < 5; ++i) worker.push(imageInput(image(200, 150, 4.0 + i)));  // 30 KB each
    WorkerCounters c = worker.counters();
    EXPECT_LE(c.queued_bytes, 200u * 1000u);
    EXPECT_EQ(c.rejected, 2u);
    const int out_of_queue = extraction_thread ? 2 : 1;  // the first, and the next one extracted
    EXPECT_TRUE(eventually([&] { return staged.load() >= out_of_queue; }));
    for (int i = 0; i < 5; ++i) worker.push(imageInput(image(300, 300, 10.0 + i)));  // 90 KB each
    c = worker.counters();
    EXPECT_LE(c.queued_bytes, 200u * 1000u);
    EXPECT_EQ(c.queued, 2u) << "two of 90 KB fit in 200 KB";
    EXPECT_EQ(c.dropped, extraction_thread ? 7u : 8u);
    hold.unlock();
    worker.waitIdle();
    c = worker.counters();
    EXPECT_EQ(c.processed + c.dropped + c.rejected, 13u) << "every keyframe accounted for";
    EXPECT_EQ(c.processed, extraction_thread ? 4u : 3u);
  }
}

TEST(Worker, AnImagesCameraIsStoredWithItsKeyframe) {
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>()));
  KeyframeWorker::Hooks hooks;
  hooks.publish = [](const ProcessedKeyframe&) {};
  KeyframeWorker worker(shared, 10, 256u << 20, InputLimits{1000 * 1000, 10000}, hooks);
  worker.start();
  const mild::CameraIntrinsics camera{300.0, 300.0, 100.0, 75.0};
  worker.push(imageInput(image(200, 150, 1.0), camera));
  worker.push(imageInput(image(200, 150, 2.0)));
  worker.waitIdle();
  ASSERT_EQ(shared.robot(0).map().size(), 2u);
  EXPECT_EQ(shared.robot(0).map().record(0).camera, camera);
  EXPECT_FALSE(shared.robot(0).map().record(1).camera.known());
}

TEST(WorkerStages, TheExtractionThreadGivesTheSameAnswersAsOneThread) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  ASSERT_EQ(frames.size(), 60u);
  Answers answers[2];
  for (const bool extraction_thread : {false, true}) {
    SharedDetector shared;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(fixtureParams())));
    KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{}, recordingHooks(answers[extraction_thread]),
                          extraction_thread);
    worker.start();
    EXPECT_EQ(worker.extractionThread(), extraction_thread);
    for (size_t i = 0; i < frames.size(); ++i) worker.push(imageInput(imageOf(frames[i], 0.5 * i)));
    worker.waitIdle();
    const WorkerCounters c = worker.counters();
    EXPECT_EQ(c.processed, frames.size());
    EXPECT_EQ(c.dropped + c.rejected + c.discarded, 0u);
  }
  const std::vector<ProcessedKeyframe>& one = answers[0].published;
  const std::vector<ProcessedKeyframe>& two = answers[1].published;
  ASSERT_EQ(one.size(), frames.size());
  ASSERT_EQ(two.size(), frames.size());
  size_t candidates = 0, accepted = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    SCOPED_TRACE("keyframe " + std::to_string(i));
    const mild::DetectionResult& a = one[i].result;
    const mild::DetectionResult& b = two[i].result;
    EXPECT_EQ(two[i].header.stamp, one[i].header.stamp) << "in arrival order";
    EXPECT_EQ(b.query_id, a.query_id);
    EXPECT_EQ(b.query_id, i);
    EXPECT_EQ(two[i].database_size, one[i].database_size);
    EXPECT_EQ(b.stats.features, a.stats.features);
    EXPECT_EQ(b.similarity, a.similarity);
    EXPECT_GT(b.stats.extract_ms, 0.0) << "the extraction ahead is still reported";
    EXPECT_GT(a.stats.extract_ms, 0.0);
    EXPECT_FALSE(two[i].image.image.empty()) << "the decoded image still reaches the debug image";
    ASSERT_EQ(b.candidates.size(), a.candidates.size());
    for (size_t c = 0; c < a.candidates.size(); ++c) {
      EXPECT_EQ(b.candidates[c].id, a.candidates[c].id);
      EXPECT_EQ(b.candidates[c].robot, a.candidates[c].robot);
      EXPECT_EQ(b.candidates[c].probability, a.candidates[c].probability);
      EXPECT_EQ(b.candidates[c].filter_probability, a.candidates[c].filter_probability);
      EXPECT_EQ(b.candidates[c].similarity, a.candidates[c].similarity);
      EXPECT_EQ(b.candidates[c].accepted, a.candidates[c].accepted);
      EXPECT_EQ(b.candidates[c].verification.inliers, a.candidates[c].verification.inliers);
      accepted += a.candidates[c].accepted ? 1 : 0;
    }
    candidates += a.candidates.size();
  }
  EXPECT_GT(candidates, 0u);
  EXPECT_GT(accepted, 0u) << "the fixture's revisit is found";
}

// Refusals by either stage (an undecodable image by stage 1, a duplicate id or another width by the
// detector in stage 2) keep their place among the answers, with the messages one thread gives.
TEST(WorkerStages, AnswersAndRefusalsKeepTheirOrderAndAddUp) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  Answers answers[2];
  for (const bool extraction_thread : {false, true}) {
    SharedDetector shared;
    mild::DetectorParams p = fixtureParams();
    p.verification.enabled = false;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(p)));
    KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{1000 * 1000, 10000},
                          recordingHooks(answers[extraction_thread]), extraction_thread);
    worker.start();
    double stamp = 1.0;
    for (size_t i = 0; i < 12; ++i) {
      worker.push(imageInput(imageOf(frames[i], stamp++)));  // ids 0, 1, ...: the next free one
      switch (i % 4) {
        case 0:
          worker.push(compressedImageInput(corruptPng(stamp++)));  // refused by stage 1, decoding
          break;
        case 1:
          worker.push(keyframeInput(keyframeMsg(stamp++, 0)));  // id 0 is taken: refused by the detector
          break;
        case 2:
          worker.push(keyframeInput(keyframeMsg(stamp++, 100000 - i, 16)));  // another width: refused too
          break;
        default:
          worker.push(keyframeInput(keyframeMsg(stamp++, 100000 - i)));  // features, an id below the images': answered
          break;
      }
    }
    worker.waitIdle();
    const WorkerCounters c = worker.counters();
    EXPECT_EQ(c.processed, 15u);
    EXPECT_EQ(c.rejected, 9u);
    EXPECT_EQ(c.processed + c.rejected + c.dropped + c.discarded, 24u);
  }
  EXPECT_EQ(answers[1].events, answers[0].events) << "the same answers and messages, in the same order";
  ASSERT_EQ(answers[1].events.size(), 24u);
  for (size_t i = 0; i < answers[1].events.size(); ++i) {
    const std::string stamp = std::to_string(static_cast<double>(i + 1));
    EXPECT_NE(answers[1].events[i].find("(stamp " + stamp + ")"), std::string::npos) << answers[1].events[i];
  }
  EXPECT_NE(answers[1].events[1].find("cannot be decoded"), std::string::npos) << answers[1].events[1];
  EXPECT_NE(answers[1].events[3].find("already in the database"), std::string::npos) << answers[1].events[3];
}

// A worker whose stages are watched: how many keyframes stage 1 has made ready, and a wait for it.
struct StageWatch {
  std::mutex mutex;
  std::condition_variable changed;
  int staged = 0;

  void onStaged() {
    {
      std::lock_guard<std::mutex> lock(mutex);
      ++staged;
    }
    changed.notify_all();
  }
  bool waitFor(int n, std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, timeout, [&] { return staged >= n; });
  }
};

// Keyframe k+1 is extracted while keyframe k is in stage 2 (here: its publish waits until stage 1
// has made the next one ready), and while the detector lock is held by someone else (a service).
// One thread cannot: the same wait runs out. Either way the worker's front-end extracts every
// image before the detector sees it (the detector takes features only).
TEST(WorkerStages, TheNextKeyframeIsExtractedWhileTheDetectorWorks) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  for (const bool extraction_thread : {true, false}) {
    SCOPED_TRACE(extraction_thread ? "extraction thread" : "one thread");
    SharedDetector shared;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(fixtureParams())));
    StageWatch watch;
    std::atomic<bool> first{true}, overlapped{false};
    std::atomic<double> first_extract_ms{0.0};
    std::atomic<int> extracted_ahead{0};
    KeyframeWorker::Hooks hooks;
    hooks.staged = [&](const std_msgs::Header&, bool has_features) {
      extracted_ahead += has_features ? 1 : 0;
      watch.onStaged();
    };
    hooks.publish = [&](const ProcessedKeyframe& k) {
      if (!first.exchange(false)) return;
      first_extract_ms = k.result.stats.extract_ms;
      // Keyframe 0 is stored and being answered: keyframe 1 gets extracted meanwhile, or never.
      overlapped = watch.waitFor(2, extraction_thread ? std::chrono::seconds(20) : std::chrono::milliseconds(300));
    };
    KeyframeWorker worker(shared, 10, 256u << 20, InputLimits{}, hooks, extraction_thread);
    worker.start();
    {
      const auto busy = shared.lock();  // a service holds the detector
      worker.push(imageInput(imageOf(frames[0], 1.0)));
      worker.push(imageInput(imageOf(frames[1], 2.0)));
      // Both modes: the front-end extracts before the detector lock is taken, never under it.
      EXPECT_TRUE(watch.waitFor(1, std::chrono::seconds(20))) << "extracted without the detector lock";
    }
    worker.waitIdle();
    EXPECT_EQ(extracted_ahead.load(), 2) << "the worker extracts, not only decodes, in both modes";
    EXPECT_EQ(overlapped.load(), extraction_thread);
    EXPECT_GT(first_extract_ms.load(), 0.0);
    EXPECT_EQ(worker.counters().processed, 2u);
  }
}

// stop() with a keyframe in each stage and more waiting: the detector's finishes and is answered,
// the one extracted (or still being extracted) and those waiting are discarded and counted, both
// threads are joined, and the worker is idle.
TEST(WorkerStages, StoppingWithKeyframesInBothStagesCountsThem) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  for (const bool handed_over : {true, false}) {
    SCOPED_TRACE(handed_over ? "keyframe 1 handed over" : "keyframe 1 being extracted");
    SharedDetector shared;
    shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(fixtureParams())));
    StageWatch watch;
    std::mutex publish_gate, stage_gate;
    std::unique_lock<std::mutex> hold_publish(publish_gate);  // keyframe 0 waits in its publish
    std::unique_lock<std::mutex> hold_stage(stage_gate, std::defer_lock);
    if (!handed_over) hold_stage.lock();  // keyframe 1 waits in stage 1, before the hand-off
    std::atomic<int> published{0};
    KeyframeWorker::Hooks hooks;
    hooks.staged = [&](const std_msgs::Header& h, bool) {
      watch.onStaged();
      if (h.stamp.toSec() == 1.0) std::lock_guard<std::mutex> wait(stage_gate);
    };
    hooks.publish = [&](const ProcessedKeyframe&) {
      ++published;
      std::lock_guard<std::mutex> wait(publish_gate);
    };
    KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{}, hooks, true);
    worker.start();
    for (int i = 0; i < 10; ++i) worker.push(imageInput(imageOf(frames[static_cast<size_t>(i)], i)));
    EXPECT_TRUE(watch.waitFor(2, std::chrono::seconds(20)));
    EXPECT_TRUE(eventually([&] { return published.load() > 0; }));
    if (handed_over) {
      EXPECT_TRUE(eventually([&] { return worker.counters().handed_over == 1; }));
    }
    EXPECT_EQ(worker.counters().queued, 8u) << "one keyframe in each stage";
    std::thread stopper([&] { worker.stop(); });
    EXPECT_TRUE(eventually([&] { return worker.counters().discarded >= (handed_over ? 9u : 8u); }));
    if (!handed_over) hold_stage.unlock();
    hold_publish.unlock();
    stopper.join();
    worker.waitIdle();  // returns: nothing is left in either stage
    const WorkerCounters c = worker.counters();
    EXPECT_EQ(c.processed, 1u) << "the detector's keyframe finished";
    EXPECT_EQ(c.discarded, 9u);
    EXPECT_EQ(c.processed + c.discarded + c.dropped + c.rejected, 10u);
    EXPECT_EQ(published.load(), 1);
    EXPECT_EQ(shared.robot(0).map().size(), 1u);
    EXPECT_EQ(worker.push(imageInput(imageOf(frames[10], 10.0))), KeyframeWorker::Pushed::kDroppedOldest)
        << "a stopped worker takes nothing";
  }
}

// discardPending (the reset service) empties the hand-off too: an extracted keyframe waiting for
// the detector is as much "waiting" as one in the queue.
TEST(WorkerStages, DiscardingPendingKeyframesEmptiesTheHandOff) {
  const std::vector<cv::Mat>& frames = mild::test::fixtureFrames();
  SharedDetector shared;
  shared.setTeam(std::make_unique<mild::RobotTeam>(std::make_unique<mild::LoopDetector>(fixtureParams())));
  StageWatch watch;
  std::mutex gate;
  std::unique_lock<std::mutex> hold(gate);
  KeyframeWorker::Hooks hooks;
  hooks.staged = [&](const std_msgs::Header&, bool) { watch.onStaged(); };
  hooks.publish = [&](const ProcessedKeyframe&) { std::lock_guard<std::mutex> wait(gate); };
  KeyframeWorker worker(shared, 100, 256u << 20, InputLimits{}, hooks, true);
  worker.start();
  for (int i = 0; i < 5; ++i) worker.push(imageInput(imageOf(frames[static_cast<size_t>(i)], i)));
  EXPECT_TRUE(watch.waitFor(2, std::chrono::seconds(20)));
  EXPECT_TRUE(eventually([&] { return worker.counters().handed_over == 1; }));
  // Keyframe 0 in stage 2, keyframe 1 extracted, 2-4 queued (stage 1 takes none until the hand-off
  // is free).
  EXPECT_EQ(worker.counters().queued, 3u);
  EXPECT_EQ(worker.discardPending(), 4u);
  EXPECT_EQ(worker.counters().handed_over, 0u);
  hold.unlock();
  worker.waitIdle();
  const WorkerCounters c = worker.counters();
  EXPECT_EQ(c.processed, 1u);
  EXPECT_EQ(c.discarded, 4u);
  worker.push(imageInput(imageOf(frames[5], 5.0)));
  worker.waitIdle();
  EXPECT_EQ(worker.counters().processed, 2u) << "and goes on";
}

}  // namespace
}  // namespace mild_lcd
