// mild_bench_team: what a keyframe costs as the team grows. For each team size R, R robots map
// their own walks at the same time (keyframes interleaved, robot 0, 1, ..., R-1, 0, ...) into one
// RobotTeam, the node's core; the CPU time of each keyframe (extraction, the queries into every
// robot's map, the filters, verification) is measured on this thread, so the figures do not depend
// on what else runs on the machine. Work per keyframe against a lone robot is the ratio that says
// how the design scales.

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include "common/tool_main.hpp"

#include "common/image_sequence.hpp"
#include "common/timing_summary.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stopwatch.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/detector/feature_front_end.hpp"
#include "mild_lcd/detector/robot_team.hpp"

namespace {

struct Options {
  std::vector<std::string> walks;
  std::vector<int> team_sizes = {1, 2, 4, 8};
  int keyframes = 1000;
  std::string config;
  bool json = false;
};

// The first `count` frames of a walk, decoded once (grey).
std::vector<cv::Mat> loadWalk(const std::string& dir, int count) {
  const mild::tools::ImageSequence seq = mild::tools::openImageSequence(dir);
  if (seq.frames.size() < static_cast<size_t>(count)) {
    throw mild::InvalidInput(dir + " holds " + std::to_string(seq.frames.size()) + " frames, fewer than --keyframes " +
                             std::to_string(count));
  }
  std::vector<cv::Mat> frames;
  for (int i = 0; i < count; ++i) {
    cv::Mat image = cv::imread(seq.frames[static_cast<size_t>(i)], cv::IMREAD_GRAYSCALE);
    if (image.empty()) throw mild::InvalidInput(seq.frames[static_cast<size_t>(i)] + ": not an image");
    frames.push_back(std::move(image));
  }
  return frames;
}

int run(const Options& opt) {
  mild::DetectorParams params;
  if (!opt.config.empty()) params = mild::loadDetectorParams(mild::YamlParameterSource::fromFile(opt.config));
  const int largest = *std::max_element(opt.team_sizes.begin(), opt.team_sizes.end());
  if (static_cast<int>(opt.walks.size()) < largest) {
    throw mild::InvalidInput("a team of " + std::to_string(largest) +
                             " needs as many --walk folders (one per robot), " + std::to_string(opt.walks.size()) +
                             " given");
  }
  std::vector<std::vector<cv::Mat>> walks;
  for (int r = 0; r < largest; ++r) walks.push_back(loadWalk(opt.walks[static_cast<size_t>(r)], opt.keyframes));

  nlohmann::json rows = nlohmann::json::array();
  double lone_median = 0.0;
  if (!opt.json) {
    std::cout << "| robots | keyframes | CPU ms per keyframe: median (p99) | x one robot | keyframes / s of CPU | "
                 "inter-robot candidates per keyframe |\n|---|---|---|---|---|---|\n";
  }
  for (int robots : opt.team_sizes) {
    std::vector<std::string> names;
    for (int r = 0; r < robots; ++r) names.push_back("robot" + std::to_string(r + 1));
    mild::RobotTeam team(params, names);
    const mild::FeatureFrontEnd front_end(params.features);
    std::vector<double> cpu_ms;
    size_t inter_robot = 0;
    for (int i = 0; i < opt.keyframes; ++i) {
      for (int r = 0; r < robots; ++r) {
        const double stamp = 0.1 * i;  // every robot at 10 Hz
        const double start = mild::threadCpuMs();
        const mild::DetectionResult result = team.process(front_end.extract(
            mild::Observation::ofImage(walks[static_cast<size_t>(r)][static_cast<size_t>(i)], mild::PixelFormat::kGray,
                                       stamp, static_cast<uint64_t>(i), {}, static_cast<size_t>(r))));
        cpu_ms.push_back(mild::threadCpuMs() - start);
        for (const mild::LoopCandidate& c : result.candidates) inter_robot += c.robot != static_cast<uint32_t>(r);
      }
    }
    const mild::tools::TimingSummary s = mild::tools::summarize(cpu_ms);
    if (robots == opt.team_sizes.front()) lone_median = s.median;
    double total = 0.0;
    for (double v : cpu_ms) total += v;
    const double per_second = 1000.0 * static_cast<double>(cpu_ms.size()) / total;
    const double inter_per_keyframe = static_cast<double>(inter_robot) / static_cast<double>(cpu_ms.size());
    rows.push_back({{"robots", robots},
                    {"keyframes", cpu_ms.size()},
                    {"cpu_ms_median", s.median},
                    {"cpu_ms_p99", s.p99},
                    {"ratio_to_first", s.median / lone_median},
                    {"keyframes_per_cpu_second", per_second},
                    {"inter_robot_candidates_per_keyframe", inter_per_keyframe}});
    if (!opt.json) {
      std::printf("| %d | %zu | %.1f (%.1f) | %.2f | %.0f | %.2f |\n", robots, cpu_ms.size(), s.median, s.p99,
                  s.median / lone_median, per_second, inter_per_keyframe);
      std::fflush(stdout);
    }
  }
  if (opt.json) std::cout << nlohmann::json{{"rows", rows}, {"keyframes_per_robot", opt.keyframes}}.dump() << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "Cost per keyframe of a team of robots in one detector (RobotTeam, the node's core): each robot maps its own "
      "walk, keyframes interleaved; CPU time on one thread, against the first team size."};
  app.name("mild_bench_team");
  Options opt;
  app.add_option("--walk", opt.walks, "image sequence of one robot (one per robot of the largest team)")->required();
  app.add_option("--robots", opt.team_sizes, "team sizes, the first is the baseline")->delimiter(',');
  app.add_option("--keyframes", opt.keyframes, "keyframes per robot")->check(CLI::PositiveNumber);
  app.add_option("--config", opt.config, "YAML parameter file (see config/default.yaml)");
  app.add_flag("--json", opt.json, "print one JSON object instead of the table");
  return mild::tools::toolMain(app, argc, argv, [&] {
    for (int r : opt.team_sizes) {
      if (r < 1) throw mild::InvalidInput("--robots: team sizes are at least 1");
    }
    return run(opt);
  });
}
