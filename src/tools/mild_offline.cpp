// mild_offline: runs the loop-closure pipeline over an image sequence, writes the candidates CSV,
// and optionally scores it against ground truth, plots it and reports per-stage timing.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>

#include <CLI/CLI.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include "common/tool_main.hpp"

#include "common/decision_line.hpp"
#include "common/image_sequence.hpp"
#include "common/npy_writer.hpp"
#include "common/progress_bar.hpp"
#include "common/timing_summary.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stopwatch.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/detector/feature_front_end.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "mild_lcd/offline/pose_evaluation.hpp"
#include "offline_plots.hpp"

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

struct Options {
  std::string images;
  std::string config;
  std::string output;
  std::string gt;
  std::string plots;
  std::string stats;
  std::string similarity;
  std::string details;
  std::string poses;
  double fps = 10.0;
  int min_gap = 40;
  bool print_config = false;
  bool help_parameters = false;
  bool fit_every_candidate = false;
  double scale = 1.0;
  int stats_window = 1000;
};

// The most pixels a frame may have after --scale (OpenCV's own limit on a decoded image).
constexpr double kMaxScaledPixels = 1024.0 * 1024.0 * 1024.0;

// Reads one frame as 8-bit grey, BGR or BGRA; nullopt when the file cannot be decoded, or when
// --scale would make it empty or larger than kMaxScaledPixels (that frame alone is skipped).
std::optional<std::pair<cv::Mat, mild::PixelFormat>> readFrame(const std::string& path, double scale) {
  cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (image.empty()) return std::nullopt;
  if (scale != 1.0) {
    const double cols = std::round(image.cols * scale), rows = std::round(image.rows * scale);
    if (cols < 1.0 || rows < 1.0 || cols * rows > kMaxScaledPixels) return std::nullopt;
    cv::resize(image, image, cv::Size(static_cast<int>(cols), static_cast<int>(rows)), 0, 0,
               scale > 1.0 ? cv::INTER_LINEAR : cv::INTER_AREA);
  }
  if (image.depth() == CV_16U) image.convertTo(image, CV_8U, 1.0 / 256.0);
  if (image.depth() != CV_8U) return std::nullopt;
  if (const auto format = mild::decodedPixelFormat(image.channels())) return std::make_pair(image, *format);
  return std::nullopt;
}

json timingJson(const std::vector<double>& samples) {
  const auto s = mild::tools::summarize(samples);
  return {{"mean", s.mean}, {"median", s.median}, {"p95", s.p95}, {"p99", s.p99}, {"max", s.max}};
}

struct EstimatedPose {
  size_t query;
  uint64_t candidate;
  mild::RelativePose pose;
};

// Per-stage times of every keyframe, in order.
struct StageTimes {
  std::vector<double> extract_ms, query_ms, filter_ms, verify_ms, keyframe_ms, keyframe_cpu_ms;
};

// What the pass over the frames gathers, besides the CSV files it writes as it goes.
struct DetectionPass {
  StageTimes times;
  std::vector<float> similarity_matrix;
  std::vector<EstimatedPose> estimated;
  size_t skipped = 0, features = 0;
};

std::ofstream openCandidatesCsv(const Options& opt) {
  std::ofstream csv(opt.output);
  if (!csv) throw mild::InvalidInput(opt.output + ": cannot write the candidates file");
  csv << "query,candidate,score\n";
  return csv;
}

// Not opened without --details.
std::ofstream openDetailsCsv(const Options& opt) {
  std::ofstream details;
  if (!opt.details.empty()) {
    details.open(opt.details);
    if (!details) throw mild::InvalidInput(opt.details + ": cannot write the details file");
    details << "query,candidate,probability,filter_probability,similarity,matches,inliers,inlier_ratio,coverage,"
               "homography_share,verified,accepted,near_past,fit_skipped,eligible,saliency,reported,log10_nfa";
    // The scorer's feature vector, as it computes it: scripts/fit_scoring.py fits on these columns.
    for (const std::string& name : mild::CandidateScorer::featureNames()) details << "," << name;
    details << "\n";
  }
  return details;
}

// The whole pipeline per keyframe (keyframe_ms) is the four stages' sum.
void recordStageTimes(const mild::StepStats& stats, StageTimes& times) {
  times.extract_ms.push_back(stats.extract_ms);
  times.query_ms.push_back(stats.query_ms);
  times.filter_ms.push_back(stats.filter_ms);
  times.verify_ms.push_back(stats.verify_ms);
  times.keyframe_ms.push_back(stats.extract_ms + stats.query_ms + stats.filter_ms + stats.verify_ms);
}

void writeDetailsRow(std::ostream& details, size_t query, const mild::DetectionResult& r, const mild::LoopCandidate& c,
                     bool reported, const mild::LoopDetector& detector) {
  const mild::Verification& v = c.verification;
  details << query << "," << c.id << "," << mild::formatScore(c.probability) << ","
          << mild::formatScore(c.filter_probability) << "," << c.similarity << "," << v.matches << "," << v.inliers
          << "," << v.inlier_ratio << "," << v.coverage << "," << v.homography_share << "," << (v.verified ? 1 : 0)
          << "," << (c.accepted ? 1 : 0) << "," << r.stats.near_past_keyframes << "," << (v.fit_skipped ? 1 : 0) << ","
          << r.stats.eligible_keyframes << "," << c.saliency << "," << (reported ? 1 : 0) << ","
          << v.log10_false_alarms;
  for (double x : detector.scorer().features(mild::LoopDetector::evidenceOf(c), v)) details << "," << x;
  details << "\n";
}

void writeCandidates(const Options& opt, size_t i, const mild::DetectionResult& r, const mild::LoopDetector& detector,
                     std::ofstream& csv, std::ofstream& details, std::vector<EstimatedPose>& estimated) {
  for (const mild::LoopCandidate& c : r.candidates) {
    // Every candidate with its published probability: one that failed verification keeps a
    // (low) probability, which ranks it below the verified ones.
    csv << i << "," << c.id << "," << mild::formatScore(c.probability) << "\n";
    if (c.verification.pose.valid) estimated.push_back({i, c.id, c.verification.pose});
    if (details.is_open()) writeDetailsRow(details, i, r, c, true, detector);
  }
  // Training data: the candidates judged but not reported (beyond detector/max_candidates) too.
  if (details.is_open() && opt.fit_every_candidate) {
    for (const mild::LoopCandidate& c : r.unreported) writeDetailsRow(details, i, r, c, false, detector);
  }
}

// Row = query frame, column = candidate frame (ids are frame indices).
void recordSimilarityRow(size_t i, size_t n, const mild::DetectionResult& r, const mild::LoopDetector& detector,
                         std::vector<float>& similarity_matrix) {
  for (size_t k = 0; k < r.similarity.size(); ++k) {
    similarity_matrix[i * n + detector.map().record(static_cast<mild::KeyframeIndex>(k)).id] =
        static_cast<float>(r.similarity[k]);
  }
}

DetectionPass detectOverSequence(const Options& opt, const mild::tools::ImageSequence& seq,
                                 mild::LoopDetector& detector, std::ofstream& csv, std::ofstream& details) {
  const size_t n = seq.frames.size();
  DetectionPass pass;
  if (!opt.similarity.empty()) pass.similarity_matrix.assign(n * n, 0.0f);
  const mild::FeatureFrontEnd front_end(detector.params().features);
  mild::tools::ProgressBar progress(n, "mild_offline");
  for (size_t i = 0; i < n; ++i) {
    progress.update(i);
    auto frame = readFrame(seq.frames[i], opt.scale);
    if (!frame) {
      ++pass.skipped;
      std::cerr << "\nwarning: frame " << i << " (" << seq.frames[i] << ") cannot be read as an image; skipped\n";
      continue;
    }
    const double cpu_start = mild::threadCpuMs();
    const mild::DetectionResult r =
        detector.process(front_end.extract(mild::Observation::ofImage(frame->first, frame->second, seq.stamps[i], i)));
    pass.times.keyframe_cpu_ms.push_back(mild::threadCpuMs() - cpu_start);
    recordStageTimes(r.stats, pass.times);
    pass.features += r.stats.features;
    writeCandidates(opt, i, r, detector, csv, details, pass.estimated);
    if (!pass.similarity_matrix.empty()) recordSimilarityRow(i, n, r, detector, pass.similarity_matrix);
  }
  progress.finish();
  return pass;
}

// Relative poses of the verified candidates that are true loops (all of them without --gt).
json reportRelativePoses(const std::vector<EstimatedPose>& estimated, const std::vector<mild::PlanarPose>& poses,
                         const std::optional<mild::GroundTruth>& truth) {
  mild::PoseErrors errors;
  for (const EstimatedPose& e : estimated) {
    if (e.candidate >= poses.size()) continue;
    if (truth && !truth->right.count({static_cast<int>(e.query), static_cast<int>(e.candidate)})) continue;
    errors.add(e.pose, poses[e.query], poses[e.candidate]);
  }
  const auto rot = mild::tools::summarize(errors.rotation_deg);
  const auto dir = mild::tools::summarize(errors.translation_deg);
  const json pose_summary = {{"poses", errors.rotation_deg.size()},
                             {"rotation_error_deg", {{"median", rot.median}, {"p95", rot.p95}}},
                             {"translation_direction_pairs", errors.translation_deg.size()},
                             {"translation_direction_error_deg", {{"median", dir.median}, {"p95", dir.p95}}}};
  if (errors.rotation_deg.empty()) {
    std::printf("relative pose: none estimated (verification needs the intrinsics verification/fx, fy, cx, cy)\n");
  } else {
    std::printf(
        "relative pose of %zu verified %s: rotation error median %.2f deg (p95 %.2f); baseline direction error"
        " median %.1f deg (p95 %.1f) over the %zu pairs >= %.1f m apart\n",
        errors.rotation_deg.size(), truth ? "true loops" : "candidates", rot.median, rot.p95, dir.median, dir.p95,
        errors.translation_deg.size(), errors.min_baseline_m);
  }
  return pose_summary;
}

// Medians per window of keyframes, in order: what each stage costs as the map grows.
json windowMedians(const StageTimes& times, size_t w) {
  json windows = json::array();
  for (size_t begin = 0; begin < times.keyframe_ms.size(); begin += w) {
    const size_t end = std::min(times.keyframe_ms.size(), begin + w);
    const auto slice = [&](const std::vector<double>& v) {
      return mild::tools::summarize(
          std::vector<double>(v.begin() + static_cast<long>(begin), v.begin() + static_cast<long>(end)));
    };
    windows.push_back({{"first", begin},
                       {"last", end - 1},
                       {"extract_ms", slice(times.extract_ms).median},
                       {"query_ms", slice(times.query_ms).median},
                       {"filter_ms", slice(times.filter_ms).median},
                       {"verify_ms", slice(times.verify_ms).median},
                       {"keyframe_ms", slice(times.keyframe_ms).median},
                       {"keyframe_cpu_ms", slice(times.keyframe_cpu_ms).median},
                       {"keyframe_cpu_ms_p99", slice(times.keyframe_cpu_ms).p99}});
  }
  return windows;
}

void writeStats(const Options& opt, const DetectionPass& pass, const mild::LoopDetector& detector, size_t n,
                const json& pose_summary) {
  const StageTimes& times = pass.times;
  json stats = {{"extract_ms", timingJson(times.extract_ms)},
                {"query_ms", timingJson(times.query_ms)},
                {"filter_ms", timingJson(times.filter_ms)},
                // The whole pipeline per keyframe: the four stages' sum (their own medians do not add up).
                {"keyframe_ms", timingJson(times.keyframe_ms)},
                // The same in this thread's CPU time: robust to other processes on the cores.
                {"keyframe_cpu_ms", timingJson(times.keyframe_cpu_ms)},
                {"keyframes", detector.map().size()},
                {"features", detector.map().database().featureCount()},
                {"memory_bytes", detector.map().memoryBytes()},
                {"index_memory_bytes", detector.map().database().index().memoryBytes()},
                {"discarded_buckets", detector.map().database().index().discardedBuckets()},
                {"frames", n},
                {"skipped_frames", pass.skipped}};
  if (detector.verifies()) stats["verify_ms"] = timingJson(times.verify_ms);
  stats["windows"] = windowMedians(times, static_cast<size_t>(opt.stats_window));
  if (!pose_summary.is_null()) stats["relative_pose"] = pose_summary;
  std::ofstream out(opt.stats);
  out << stats.dump(2) << "\n";
  if (!out) throw mild::InvalidInput(opt.stats + ": cannot write the stats file");
}

// Score what was written, exactly as the referee reads it; the hard decision at the configuration's
// scoring/decision_probability.
void scoreCandidates(const Options& opt, const mild::GroundTruth& truth, size_t n, double decision_probability) {
  const mild::Metrics m = mild::evaluate(truth, mild::loadCandidates(opt.output), opt.min_gap);
  std::printf("recall@100%%P: %.4f\naverage precision: %.4f\nmax F1: %.4f\n", m.recall_at_100_precision,
              m.average_precision, m.max_f1);
  std::printf("loop queries: %zu, scored queries: %zu, true positives: %zu, false positives: %zu\n", m.loop_queries,
              m.scored_queries, m.true_positives, m.false_positives);
  const mild::Decision decision =
      mild::decideAt(truth, mild::loadCandidates(opt.output), decision_probability, opt.min_gap);
  std::printf("%s\n", mild::tools::decisionLine(decision).c_str());
  if (!opt.plots.empty()) {
    mild::tools::writeOfflinePlots(opt.plots, truth, mild::loadCandidates(opt.output), m, decision, n, opt.min_gap);
  }
}

int run(const Options& opt) {
  mild::DetectorParams params;
  if (!opt.config.empty()) params = mild::loadDetectorParams(mild::YamlParameterSource::fromFile(opt.config));
  if (opt.help_parameters) {
    std::cout << mild::parameterMarkdown();
    return 0;
  }
  // Training data for the scorer (scripts/fit_scoring.py) needs every candidate's inliers.
  if (opt.fit_every_candidate) params.verification.early_stop = false;
  if (opt.print_config) {
    std::cout << mild::parameterYaml(params);
    if (opt.images.empty()) return 0;
  }
  if (opt.images.empty() || opt.output.empty()) {
    throw mild::InvalidInput("--images and --output are required (or --print-config alone)");
  }
  const mild::tools::ImageSequence seq = mild::tools::openImageSequence(opt.images, opt.fps);
  std::optional<mild::GroundTruth> truth;
  if (!opt.gt.empty())
    truth = mild::loadGroundTruth(opt.gt, static_cast<long>(seq.frames.size()));  // fail before the long run, not after
  std::vector<mild::PlanarPose> poses;
  if (!opt.poses.empty()) poses = mild::loadPlanarPoses(opt.poses, static_cast<long>(seq.frames.size()));
  for (const auto& f : seq.ignored) std::cerr << "note: ignoring non-image file " << f << "\n";

  std::ofstream csv = openCandidatesCsv(opt);
  std::ofstream details = openDetailsCsv(opt);

  mild::LoopDetector detector(params);
  const size_t n = seq.frames.size();
  const DetectionPass pass = detectOverSequence(opt, seq, detector, csv, details);
  csv.close();
  if (!csv) throw mild::InvalidInput(opt.output + ": write failed");
  if (pass.skipped == n)
    throw mild::InvalidInput(seq.image_dir + ": none of the " + std::to_string(n) + " image files could be read");

  std::cout << "processed " << (n - pass.skipped) << " of " << n << " frames (" << pass.skipped
            << " unreadable, skipped), " << pass.features / std::max<size_t>(1, n - pass.skipped)
            << " features per frame\n";
  std::cout << "candidates: " << opt.output << "\n";

  if (!opt.similarity.empty()) {
    if (!mild::tools::writeNpyFloat32(opt.similarity, pass.similarity_matrix, n, n)) {
      throw mild::InvalidInput(opt.similarity + ": cannot write the similarity matrix");
    }
  }

  json pose_summary;
  if (!poses.empty()) pose_summary = reportRelativePoses(pass.estimated, poses, truth);

  if (!opt.stats.empty()) writeStats(opt, pass, detector, n, pose_summary);

  if (truth) {
    scoreCandidates(opt, *truth, n, params.scoring.decision_probability);
  } else if (!opt.plots.empty()) {
    std::cerr << "note: --plots needs --gt (the plots compare detections with ground truth); no plots written\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Run mild_lcd loop-closure detection over an image sequence (offline runner and evaluator)."};
  app.name("mild_offline");
  Options opt;
  app.add_option("--images", opt.images, "folder of frames in file-name order, or a folder with an images/ subfolder");
  app.add_option("--config", opt.config, "YAML parameter file (see config/default.yaml)");
  app.add_option("--output", opt.output, "candidates CSV to write (query,candidate,score)");
  app.add_option("--gt", opt.gt,
                 "ground-truth gt_loops.txt: print recall@100%P, average precision, max F1, and precision and recall "
                 "at the configuration's scoring/decision_probability");
  app.add_option("--plots", opt.plots, "folder for pr_curve.png and loops_matrix.png (needs --gt)");
  app.add_option("--stats", opt.stats, "JSON file for per-stage timing and database size");
  app.add_option("--details", opt.details,
                 "CSV of every candidate with probability, similarity, matches, inliers and the verdict");
  app.add_option("--poses", opt.poses,
                 "poses.txt (x y yaw per frame): report the relative-pose errors of verified true loops "
                 "(needs the camera intrinsics in --config)");
  app.add_option("--similarity", opt.similarity, "write the raw similarity matrix (frames x frames, float32 .npy)");
  app.add_option("--fps", opt.fps, "frame rate for time stamps when the sequence has no times.txt")
      ->check(CLI::PositiveNumber);
  app.add_option("--min-gap", opt.min_gap,
                 "pairs closer than this many frames are ignored when scoring (EVALUATION.md: 40)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--fit-every-candidate", opt.fit_every_candidate,
               "verification/early_stop off: every candidate's model fitted, and --details lists the candidates judged "
               "beyond detector/max_candidates too (column reported 0), as scripts/fit_scoring.py needs (each "
               "keyframe's best candidate, and what is accepted, are the same either way)");
  app.add_option("--scale", opt.scale,
                 "resize every frame by this factor before detection (speed at other image sizes, e.g. 2 for 640 x 480 "
                 "from 320 x 240)")
      ->check(CLI::Range(0.1, 8.0));
  app.add_option("--stats-window", opt.stats_window,
                 "--stats also gives each stage's median per window of this many keyframes, in order")
      ->check(CLI::Range(1, 1000000));
  app.add_flag("--print-config", opt.print_config,
               "print the effective parameters as YAML, with their bounds and meaning (alone: and exit; with the "
               "defaults it is config/default.yaml)");
  app.add_flag("--help-parameters", opt.help_parameters,
               "print the detector's parameters as a Markdown table and exit");
  return mild::tools::toolMain(app, argc, argv, [&] { return run(opt); });
}
