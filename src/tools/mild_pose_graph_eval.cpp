// mild_pose_graph_eval: the example back-end measured on a sequence with ground truth, offline.
// Runs the detector over the sequence's frames (with the camera's intrinsics, so verified loops carry
// a relative pose), makes odometry with drift from poses.txt (backend/trajectory.hpp's model), feeds
// keyframes and accepted loops to the pose graph in arrival order, optimising after each keyframe
// that brought a loop, and prints the absolute trajectory error (ATE RMSE after SE(2) alignment)
// of the odometry and of the corrected trajectory; then the same with a fraction of the loops
// replaced by wrong ones (random keyframe pairs more than 10 m apart carrying the replaced loop's
// measurement), and the time of one update (median, p95, max).

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <optional>
#include <random>
#include <sstream>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include "common/drift_options.hpp"
#include "common/tool_main.hpp"

#include "common/image_sequence.hpp"
#include "common/progress_bar.hpp"
#include "common/timing_summary.hpp"
#include "mild_lcd/backend/pose_graph.hpp"
#include "mild_lcd/backend/trajectory.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/detector/feature_front_end.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "mild_lcd/offline/pose_evaluation.hpp"
#include "offline_plots.hpp"

namespace {

using json = nlohmann::json;
using mild::backend::LoopMeasurement;
using mild::backend::Pose2;

struct Options {
  std::string sequence, config, graph_config, save_loops, load_loops, trajectories, plot, json_out;
  std::string odometry_out;
  mild::backend::DriftModel drift;
  double wrong_fraction = 0.05;
  uint64_t wrong_seed = 1;
  long frames = -1;
  bool help_parameters = false;
};

// The loops a detector publishes as accepted, with their relative pose (LoopCandidate's fields).
std::vector<LoopMeasurement> detectLoops(const Options& opt, const mild::tools::ImageSequence& seq, size_t n,
                                         std::vector<double>& detector_ms) {
  mild::DetectorParams params;
  if (!opt.config.empty()) params = mild::loadDetectorParams(mild::YamlParameterSource::fromFile(opt.config));
  if (params.verification.fx <= 0.0) {
    throw mild::InvalidInput(
        "the detector needs the camera's intrinsics (verification/fx, ...: --config "
        "config/bench_camera.yaml) for loops with a relative pose");
  }
  mild::LoopDetector detector(params);
  const mild::FeatureFrontEnd front_end(params.features);
  std::vector<LoopMeasurement> loops;
  mild::tools::ProgressBar progress(n, "mild_pose_graph_eval");
  for (size_t i = 0; i < n; ++i) {
    progress.update(i);
    const cv::Mat image = cv::imread(seq.frames[i], cv::IMREAD_GRAYSCALE);
    if (image.empty()) throw mild::InvalidInput(seq.frames[i] + ": cannot read the image");
    const mild::DetectionResult r = detector.process(
        front_end.extract(mild::Observation::ofImage(image, mild::PixelFormat::kGray, seq.stamps[i], i)));
    detector_ms.push_back(r.stats.extract_ms + r.stats.query_ms + r.stats.filter_ms + r.stats.verify_ms);
    for (const mild::LoopCandidate& c : r.candidates) {
      const mild::RelativePose& p = c.verification.pose;
      if (!c.accepted || !p.valid) continue;
      LoopMeasurement m;
      m.query = i;
      m.candidate = c.id;
      Eigen::Matrix3d rotation;
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) rotation(a, b) = p.rotation(a, b);
      m.rotation = Eigen::Quaterniond(rotation);
      m.translation = Eigen::Vector3d(p.translation[0], p.translation[1], p.translation[2]);
      m.metric = p.metric;
      loops.push_back(m);
    }
  }
  progress.finish();
  return loops;
}

void saveLoops(const std::string& path, const std::vector<LoopMeasurement>& loops) {
  std::ofstream out(path);
  if (!out) throw mild::InvalidInput(path + ": cannot write the loops file");
  out << "query,candidate,qw,qx,qy,qz,tx,ty,tz,metric\n" << std::setprecision(17);
  for (const LoopMeasurement& m : loops) {
    out << m.query << "," << m.candidate << "," << m.rotation.w() << "," << m.rotation.x() << "," << m.rotation.y()
        << "," << m.rotation.z() << "," << m.translation.x() << "," << m.translation.y() << "," << m.translation.z()
        << "," << (m.metric ? 1 : 0) << "\n";
  }
}

std::vector<LoopMeasurement> loadLoops(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw mild::InvalidInput(path + ": cannot read the loops file");
  std::vector<LoopMeasurement> loops;
  std::string line;
  std::getline(in, line);
  size_t number = 1;
  while (std::getline(in, line)) {
    ++number;
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream f(line);
    LoopMeasurement m;
    double w, x, y, z;
    int metric;
    if (!(f >> m.query >> m.candidate >> w >> x >> y >> z >> m.translation.x() >> m.translation.y() >>
          m.translation.z() >> metric)) {
      throw mild::InvalidInput(path + ":" + std::to_string(number) + ": malformed loop");
    }
    m.rotation = Eigen::Quaterniond(w, x, y, z);
    m.metric = metric != 0;
    loops.push_back(m);
  }
  return loops;
}

// `fraction` of the loops (at least one when there are any and fraction > 0) get a wrong
// candidate: a random earlier frame more than 10 m from the query, at least 40 frames back; the
// measurement stays the replaced loop's.
std::vector<LoopMeasurement> withWrongLoops(std::vector<LoopMeasurement> loops, const std::vector<Pose2>& truth,
                                            double fraction, uint64_t seed, size_t& replaced) {
  replaced = 0;
  if (loops.empty() || fraction <= 0.0) return loops;
  std::mt19937_64 rng(seed);
  const size_t count = std::max<size_t>(1, static_cast<size_t>(std::lround(fraction * loops.size())));
  std::vector<size_t> order(loops.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  for (size_t k = 0; k < order.size() && replaced < count; ++k) {
    LoopMeasurement& m = loops[order[k]];
    std::vector<uint64_t> far;
    for (uint64_t j = 0; j + 40 <= m.query; ++j) {
      if (std::hypot(truth[j].x - truth[m.query].x, truth[j].y - truth[m.query].y) > 10.0) far.push_back(j);
    }
    if (far.empty()) continue;
    m.candidate = far[std::uniform_int_distribution<size_t>(0, far.size() - 1)(rng)];
    ++replaced;
  }
  return loops;
}

struct GraphRun {
  std::vector<Pose2> estimate;
  std::vector<mild::backend::LoopEdgeState> loops;
  std::vector<double> update_ms;
};

GraphRun runGraph(const mild::backend::PoseGraphParams& params, const std::vector<Pose2>& odometry,
                  const std::vector<LoopMeasurement>& loops) {
  mild::backend::PoseGraph2D graph(params);
  GraphRun out;
  size_t next = 0;
  std::vector<LoopMeasurement> sorted = loops;
  std::stable_sort(sorted.begin(), sorted.end(),
                   [](const LoopMeasurement& a, const LoopMeasurement& b) { return a.query < b.query; });
  for (size_t i = 0; i < odometry.size(); ++i) {
    graph.addKeyframe(i, odometry[i]);
    bool added = false;
    while (next < sorted.size() && sorted[next].query == i) added |= graph.addLoop(sorted[next++]);
    if (added) out.update_ms.push_back(graph.optimize().solve_ms);
  }
  graph.optimize();
  out.estimate = graph.estimates();
  out.loops = graph.loops();
  return out;
}

std::string fixed(double v, int digits) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

mild::backend::PoseGraphParams loadGraphParams(const std::string& graph_config) {
  mild::backend::PoseGraphParams graph_params;
  if (!graph_config.empty()) {
    graph_params = mild::backend::loadPoseGraphParams(mild::YamlParameterSource::fromFile(graph_config));
  }
  return graph_params;
}

void printParameterTable() {
  std::cout << "| parameter | default | range | meaning |\n|---|---|---|---|\n"
            << mild::backend::poseGraphParameterMarkdown("graph/");
}

// The first n poses of the sequence's poses.txt.
std::vector<Pose2> truthOf(const Options& opt, const mild::tools::ImageSequence& seq, size_t n) {
  const std::vector<mild::PlanarPose> planar = mild::loadPlanarPoses(
      (std::filesystem::path(opt.sequence) / "poses.txt").string(), static_cast<long>(seq.frames.size()));
  std::vector<Pose2> truth;
  for (size_t i = 0; i < n; ++i) truth.push_back({planar[i].x, planar[i].y, planar[i].yaw});
  return truth;
}

void writeOdometry(const std::string& path, const std::vector<Pose2>& odometry) {
  std::ofstream out(path);
  if (!out) throw mild::InvalidInput(path + ": cannot write the odometry");
  out << std::setprecision(10);
  for (const Pose2& p : odometry) out << p.x << " " << p.y << " " << p.yaw << "\n";
}

// --load-loops' loops among the first n frames, or the detector's (with its time per keyframe).
std::vector<LoopMeasurement> loadOrDetectLoops(const Options& opt, const mild::tools::ImageSequence& seq, size_t n,
                                               std::vector<double>& detector_ms) {
  std::vector<LoopMeasurement> loops;
  if (!opt.load_loops.empty()) {
    loops = loadLoops(opt.load_loops);
    loops.erase(std::remove_if(loops.begin(), loops.end(),
                               [&](const LoopMeasurement& m) { return m.query >= n || m.candidate >= n; }),
                loops.end());
  } else {
    loops = detectLoops(opt, seq, n, detector_ms);
  }
  return loops;
}

struct Figures {
  size_t keyframes = 0;
  double length = 0.0;
  size_t loops = 0, metric = 0;
  double before = 0.0, after = 0.0, after_wrong = 0.0;  // ATE RMSE: odometry, clean graph, graph with wrong loops
  size_t rejected = 0, replaced = 0, wrong_rejected = 0, wrong_kept = 0;
  // The detector's own wrong loops by the sequence's gt_loops.txt (neither right nor don't-care),
  // in the clean graph: what the robust loss did with each.
  bool own_judged = false;
  size_t own_wrong_rejected = 0, own_wrong_kept = 0;
  std::vector<double> updates;  // both graphs' update times
  mild::tools::TimingSummary timing;
};

Figures measure(const std::vector<Pose2>& truth, const std::vector<Pose2>& odometry,
                const std::vector<LoopMeasurement>& loops, const GraphRun& clean, const GraphRun& wrong,
                size_t replaced, const mild::GroundTruth* own_truth) {
  Figures f;
  f.keyframes = truth.size();
  f.replaced = replaced;
  f.before = mild::backend::absoluteTrajectoryError(odometry, truth);
  f.after = mild::backend::absoluteTrajectoryError(clean.estimate, truth);
  f.after_wrong = mild::backend::absoluteTrajectoryError(wrong.estimate, truth);
  f.updates = clean.update_ms;
  f.updates.insert(f.updates.end(), wrong.update_ms.begin(), wrong.update_ms.end());
  f.timing = mild::tools::summarize(f.updates);
  for (const auto& l : clean.loops) f.rejected += !l.inlier;
  for (size_t k = 0; k < wrong.loops.size(); ++k) {
    const auto& l = wrong.loops[k];
    const bool is_wrong =
        std::hypot(truth[l.query].x - truth[l.candidate].x, truth[l.query].y - truth[l.candidate].y) > 10.0;
    if (is_wrong) (l.inlier ? f.wrong_kept : f.wrong_rejected) += 1;
  }
  if (own_truth) {
    f.own_judged = true;
    for (const auto& l : clean.loops) {
      const std::pair<int, int> pair(static_cast<int>(l.query), static_cast<int>(l.candidate));
      if (own_truth->right.count(pair) || own_truth->dont_care.count(pair)) continue;
      (l.inlier ? f.own_wrong_kept : f.own_wrong_rejected) += 1;
    }
  }
  f.loops = loops.size();
  for (const auto& l : loops) f.metric += l.metric;
  f.length = mild::backend::pathLength(truth);
  return f;
}

void printFigures(const Options& opt, const Figures& f, const std::vector<double>& detector_ms) {
  std::cout << "sequence " << opt.sequence << ": " << f.keyframes << " keyframes, " << fixed(f.length, 1) << " m, "
            << f.loops << " accepted loops with a relative pose (" << f.metric << " metric)\n";
  std::cout << "ATE RMSE odometry " << fixed(f.before, 3) << " m, after the pose graph " << fixed(f.after, 3)
            << " m (ratio " << fixed(f.after / f.before, 3) << "; " << f.rejected << " loops rejected by the loss)\n";
  std::cout << "with " << f.replaced << " of " << f.loops << " loops wrong: ATE " << fixed(f.after_wrong, 3)
            << " m (ratio " << fixed(f.after_wrong / f.before, 3) << "; wrong loops rejected " << f.wrong_rejected
            << ", kept " << f.wrong_kept << ")\n";
  if (f.own_judged) {
    std::cout << "the detector's own wrong loops (gt_loops.txt): " << f.own_wrong_rejected + f.own_wrong_kept
              << ", rejected by the loss " << f.own_wrong_rejected << ", kept " << f.own_wrong_kept << "\n";
  }
  std::cout << "update time: " << f.updates.size() << " updates, median " << fixed(f.timing.median, 1) << " ms, p95 "
            << fixed(f.timing.p95, 1) << " ms, max " << fixed(f.timing.max, 1) << " ms";
  if (!detector_ms.empty()) {
    std::cout << " (detector per keyframe: median " << fixed(mild::tools::summarize(detector_ms).median, 1) << " ms)";
  }
  std::cout << "\n";
}

void writeJson(const Options& opt, const Figures& f) {
  json j = {{"sequence", opt.sequence},
            {"keyframes", f.keyframes},
            {"length_m", f.length},
            {"loops", f.loops},
            {"metric_loops", f.metric},
            {"ate_before", f.before},
            {"ate_after", f.after},
            {"ratio", f.after / f.before},
            {"rejected", f.rejected},
            {"wrong_loops", f.replaced},
            {"ate_after_wrong", f.after_wrong},
            {"ratio_wrong", f.after_wrong / f.before},
            {"wrong_rejected", f.wrong_rejected},
            {"wrong_kept", f.wrong_kept},
            {"own_wrong_rejected", f.own_wrong_rejected},
            {"own_wrong_kept", f.own_wrong_kept},
            {"updates", f.updates.size()},
            {"update_ms", {{"median", f.timing.median}, {"p95", f.timing.p95}, {"max", f.timing.max}}},
            {"drift",
             {{"scale_error", opt.drift.scale_error},
              {"translation_noise", opt.drift.translation_noise},
              {"heading_bias", opt.drift.heading_bias},
              {"heading_random_walk", opt.drift.heading_random_walk},
              {"seed", opt.drift.seed}}}};
  std::ofstream out(opt.json_out);
  if (!out) throw mild::InvalidInput(opt.json_out + ": cannot write");
  out << j.dump(2) << "\n";
}

// The trajectories (truth, aligned odometry, aligned estimate) and the clean graph's loops, as CSV
// for --trajectories, and drawn with --plot.
void writeTrajectories(const Options& opt, const std::vector<Pose2>& truth, const std::vector<Pose2>& odometry,
                       const GraphRun& clean, const Figures& f) {
  const std::string path = opt.trajectories.empty() ? opt.plot + ".csv" : opt.trajectories;
  const Pose2 a_odo = mild::backend::alignTrajectory(odometry, truth);
  const Pose2 a_after = mild::backend::alignTrajectory(clean.estimate, truth);
  std::ofstream out(path);
  if (!out) throw mild::InvalidInput(path + ": cannot write the trajectories");
  out << "frame,true_x,true_y,odometry_x,odometry_y,after_x,after_y\n" << std::setprecision(8);
  for (size_t i = 0; i < f.keyframes; ++i) {
    const Pose2 o = mild::backend::compose(a_odo, odometry[i]);
    const Pose2 e = mild::backend::compose(a_after, clean.estimate[i]);
    out << i << "," << truth[i].x << "," << truth[i].y << "," << o.x << "," << o.y << "," << e.x << "," << e.y << "\n";
  }
  out.close();
  const std::string loops_path = path + ".loops.csv";
  std::ofstream lo(loops_path);
  lo << "query,candidate,inlier\n";
  for (const auto& l : clean.loops) lo << l.query << "," << l.candidate << "," << (l.inlier ? 1 : 0) << "\n";
  lo.close();
  if (!opt.plot.empty()) {
    const std::string command = "/usr/bin/python3 '" + mild::tools::findScript("plot_pose_graph.py") + "' '" + path +
                                "' '" + loops_path + "' '" + opt.plot + "' --title '" +
                                std::filesystem::path(opt.sequence).filename().string() + ": ATE " +
                                fixed(f.before, 2) + " m -> " + fixed(f.after, 2) + " m'";
    if (std::system(command.c_str()) != 0) throw mild::InvalidInput("plotting failed: " + command);
  }
}

int run(const Options& opt) {
  const mild::backend::PoseGraphParams graph_params = loadGraphParams(opt.graph_config);
  if (opt.help_parameters) {
    printParameterTable();
    return 0;
  }
  if (opt.sequence.empty()) throw mild::InvalidInput("--sequence is required");
  const mild::tools::ImageSequence seq = mild::tools::openImageSequence(opt.sequence);
  size_t n = seq.frames.size();
  if (opt.frames > 0) n = std::min(n, static_cast<size_t>(opt.frames));
  const std::vector<Pose2> truth = truthOf(opt, seq, n);
  const std::vector<Pose2> odometry = mild::backend::driftedOdometry(truth, opt.drift);
  if (!opt.odometry_out.empty()) writeOdometry(opt.odometry_out, odometry);

  std::vector<double> detector_ms;
  const std::vector<LoopMeasurement> loops = loadOrDetectLoops(opt, seq, n, detector_ms);
  if (!opt.save_loops.empty()) saveLoops(opt.save_loops, loops);

  const GraphRun clean = runGraph(graph_params, odometry, loops);
  size_t replaced = 0;
  const std::vector<LoopMeasurement> corrupted =
      withWrongLoops(loops, truth, opt.wrong_fraction, opt.wrong_seed, replaced);
  const GraphRun wrong = runGraph(graph_params, odometry, corrupted);

  // Loops are keyed by frame index (detectLoops gives each frame its index as id).
  std::optional<mild::GroundTruth> own_truth;
  const std::filesystem::path gt = std::filesystem::path(opt.sequence) / "gt_loops.txt";
  if (std::filesystem::exists(gt)) own_truth = mild::loadGroundTruth(gt.string(), static_cast<long>(n));
  const Figures figures = measure(truth, odometry, loops, clean, wrong, replaced, own_truth ? &*own_truth : nullptr);
  printFigures(opt, figures, detector_ms);
  if (!opt.json_out.empty()) writeJson(opt, figures);
  if (!opt.trajectories.empty() || !opt.plot.empty()) writeTrajectories(opt, truth, odometry, clean, figures);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Measure the example pose-graph back-end on a sequence with ground truth (poses.txt)."};
  app.name("mild_pose_graph_eval");
  Options opt;
  app.add_option("--sequence", opt.sequence, "sequence folder (images/, times.txt, poses.txt)");
  app.add_option("--config", opt.config,
                 "detector parameters, with the camera's intrinsics (config/bench_camera.yaml)");
  app.add_option("--graph-config", opt.graph_config, "pose-graph parameters (a YAML with a graph: section)");
  app.add_option("--frames", opt.frames, "only the first N frames");
  mild::tools::addDriftOptions(app, opt.drift, "--seed");
  app.add_option("--wrong-fraction", opt.wrong_fraction, "fraction of the loops replaced by wrong ones")
      ->capture_default_str();
  app.add_option("--wrong-seed", opt.wrong_seed, "seed of the wrong loops")->capture_default_str();
  app.add_option("--save-loops", opt.save_loops, "write the detected loops (CSV) for --load-loops");
  app.add_option("--load-loops", opt.load_loops, "read the loops from a --save-loops file instead of detecting");
  app.add_option("--odometry", opt.odometry_out, "write the drifted odometry (x y yaw per frame)");
  app.add_option("--trajectories", opt.trajectories, "write truth, odometry and corrected trajectory (CSV)");
  app.add_option("--plot", opt.plot, "draw them with the loop edges into this PNG (matplotlib)");
  app.add_option("--json", opt.json_out, "write the figures as JSON");
  app.add_flag("--help-parameters", opt.help_parameters, "print the pose graph's parameters as a Markdown table");
  return mild::tools::toolMain(app, argc, argv, [&] { return run(opt); });
}
