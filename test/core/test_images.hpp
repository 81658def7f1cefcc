#pragma once

// The images the core tests run on, read once per test binary: the fixture (every 5th frame of the
// sample: 60 frames, a revisit at 47-59) and the embedded sample (300 frames of pub_corridor).

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

namespace mild::test {

inline const std::string kFixtureDir = std::string(MILD_SOURCE_DIR) + "/test/data/corridor_stride5";
inline const std::string kSampleDir = std::string(MILD_SOURCE_DIR) + "/sample/corridor";

// Every image of `dir`/images in file-name order, as 8-bit grey.
inline std::vector<cv::Mat> readGreyImages(const std::string& dir) {
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(dir + "/images")) files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  std::vector<cv::Mat> out;
  for (const auto& f : files) out.push_back(cv::imread(f, cv::IMREAD_GRAYSCALE));
  return out;
}

inline const std::vector<cv::Mat>& fixtureFrames() {
  static const std::vector<cv::Mat> frames = readGreyImages(kFixtureDir);
  return frames;
}

inline const std::vector<cv::Mat>& sampleFrames() {
  static const std::vector<cv::Mat> frames = readGreyImages(kSampleDir);
  return frames;
}

}  // namespace mild::test
