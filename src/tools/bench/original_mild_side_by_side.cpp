// The original MILD (lhanaf/MILD, 2017–2019) and mild_lcd side by side: the same frames, the same
// OpenCV ORB descriptors, one thread, whole passes over the sequence alternated so that both see
// the same machine load. Not part of the catkin build (it needs the original sources, which this
// package does not carry): scripts/bench_original_mild.sh compiles it against a checkout.
//
// Timed per frame, everything the loop-closure stage does after extraction:
//   original: LoopClosureDetector::insert_and_query_database + BayesianFilter::filter, as its
//             main.cpp runs them (16 tables, probe depth 0, settings.yaml's filter parameters);
//   mild_lcd: LoopDetector::process on the same keypoints and descriptors (default parameters,
//             geometric verification off: the original has none).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "../common/timing_summary.hpp"
#include "MILD/BayesianFilter.hpp"
#include "MILD/loop_closure_detector.h"
#include "mild_lcd/common/stopwatch.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/features/descriptor.hpp"

namespace {

struct Frames {
  std::vector<std::vector<cv::KeyPoint>> keypoints;
  std::vector<cv::Mat> descriptors;
};

Frames extract(const std::string& dir) {
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) files.push_back(entry.path().string());
  std::sort(files.begin(), files.end());
  // The original main.cpp's extraction: OpenCV's ORB with 800 features (FAST threshold 20).
  cv::Ptr<cv::ORB> orb = cv::ORB::create();
  orb->setMaxFeatures(800);
  Frames frames;
  for (const std::string& file : files) {
    const cv::Mat image = cv::imread(file);
    if (image.empty()) continue;
    std::vector<cv::KeyPoint> keypoints;
    cv::Mat descriptors;
    orb->detectAndCompute(image, cv::noArray(), keypoints, descriptors);
    if (descriptors.empty()) descriptors = cv::Mat(0, 32, CV_8U);
    frames.keypoints.push_back(std::move(keypoints));
    frames.descriptors.push_back(descriptors);
  }
  return frames;
}

mild::tools::TimingSummary runOriginal(const Frames& frames) {
  MILD::LoopClosureDetector detector(FEATURE_TYPE_ORB, 16, 0);
  MILD::BayesianFilter filter(0.6f, 4, 4.0f, 60);  // settings.yaml
  Eigen::VectorXf probability(1);
  probability << 0.1f;
  std::vector<Eigen::VectorXf> flags;
  std::vector<double> ms;
  for (const cv::Mat& d : frames.descriptors) {
    const auto start = mild::Clock::now();
    std::vector<float> score;
    detector.insert_and_query_database(d, score);
    filter.filter(score, probability, flags);
    ms.push_back(mild::msSince(start));
  }
  return mild::tools::summarize(ms);
}

mild::tools::TimingSummary runMildLcd(const Frames& frames) {
  mild::DetectorParams params;
  params.verification.enabled = false;
  mild::LoopDetector detector(params);
  std::vector<double> ms;
  for (size_t i = 0; i < frames.descriptors.size(); ++i) {
    mild::Features features;
    features.keypoints = frames.keypoints[i];
    features.descriptors = mild::descriptorsFromMat(frames.descriptors[i]);
    const auto start = mild::Clock::now();
    detector.process(std::move(features), static_cast<double>(i) / 10.0, i);
    ms.push_back(mild::msSince(start));
  }
  return mild::tools::summarize(ms);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s IMAGE_DIR [passes per detector, default 3]\n", argv[0]);
    return 2;
  }
  const int passes = argc > 2 ? std::max(1, std::atoi(argv[2])) : 3;
  const Frames frames = extract(argv[1]);
  size_t keypoints = 0;
  for (const auto& k : frames.keypoints) keypoints += k.size();
  std::printf("%s: %zu frames, %.0f keypoints per frame\n", argv[1], frames.descriptors.size(),
              frames.descriptors.empty() ? 0.0 : static_cast<double>(keypoints) / frames.descriptors.size());
  for (int pass = 0; pass < passes; ++pass) {
    const mild::tools::TimingSummary original = runOriginal(frames);
    const mild::tools::TimingSummary ours = runMildLcd(frames);
    std::printf(
        "pass %d  original MILD mean %.3f median %.3f p95 %.3f ms | mild_lcd mean %.3f median %.3f p95 %.3f ms | "
        "original / mild_lcd (means) %.2f\n",
        pass, original.mean, original.median, original.p95, ours.mean, ours.median, ours.p95,
        original.mean / ours.mean);
  }
  return 0;
}
