// mild_bench_match: sparse match against OpenCV's matchers on real image pairs, one thread, in one
// run, so that the ratios do not depend on how busy the machine is.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <random>

#include <CLI/CLI.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/flann.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include "common/tool_main.hpp"

#include "common/image_sequence.hpp"
#include "common/timing_summary.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/orb_extractor.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "mild_lcd/verification/sparse_matcher.hpp"

namespace {

using Clock = std::chrono::steady_clock;

struct Options {
  std::string images;
  int pairs = 200;
  int features = 1200;
  int repeats = 3;
  int num_tables = mild::SparseMatchParams{}.num_tables;
  int radius = 0;
  int valid_distance = 50;
  double scale = 1.0;
  bool json = false;
};

struct Frame {
  cv::Mat descriptors;
  mild::DescriptorList list;
};

// Time of the fastest of `repeats` runs: the least disturbed by the rest of the machine.
template <class F>
double fastestMs(int repeats, F&& f) {
  double best = 1e300;
  for (int r = 0; r < repeats; ++r) {
    const auto start = Clock::now();
    f();
    best = std::min(best, std::chrono::duration<double, std::milli>(Clock::now() - start).count());
  }
  return best;
}

// The fraction of brute-force nearest-neighbour pairs closer than `valid` that a method also
// found (same train feature, or one at the same distance).
struct Recovery {
  size_t valid = 0, recovered = 0;
  void add(const std::vector<cv::DMatch>& bf, const std::vector<int>& found_train,
           const std::vector<int>& found_distance, int valid_distance) {
    for (const cv::DMatch& m : bf) {
      if (m.distance >= valid_distance) continue;
      ++valid;
      const int q = m.queryIdx;
      if (found_train[q] == m.trainIdx || (found_train[q] >= 0 && found_distance[q] == static_cast<int>(m.distance))) {
        ++recovered;
      }
    }
  }
  double fraction() const { return valid ? static_cast<double>(recovered) / static_cast<double>(valid) : 0.0; }
};

int run(const Options& opt) {
  cv::setNumThreads(1);
  const mild::tools::ImageSequence seq = mild::tools::openImageSequence(opt.images);

  // Pairs: consecutive frames, and loop-closing frames when the sequence has ground truth.
  std::vector<std::pair<size_t, size_t>> pairs;
  const size_t n = seq.frames.size();
  std::vector<std::pair<size_t, size_t>> loops;
  try {
    const mild::GroundTruth gt = mild::loadGroundTruth(seq.root + "/gt_loops.txt");
    for (const auto& [i, j] : gt.right) {
      if (static_cast<size_t>(i) < n) loops.emplace_back(i, j);
    }
  } catch (const mild::InvalidInput&) {
  }
  std::mt19937 rng(1);
  std::shuffle(loops.begin(), loops.end(), rng);
  const size_t want = static_cast<size_t>(opt.pairs);
  const size_t loop_pairs = std::min(loops.size(), want / 2);
  pairs.assign(loops.begin(), loops.begin() + static_cast<long>(loop_pairs));
  const size_t consecutive = want - loop_pairs;
  for (size_t k = 0; k < consecutive && n > 1; ++k) {
    const size_t i = (k * (n - 1)) / std::max<size_t>(1, consecutive);
    pairs.emplace_back(i + 1, i);
  }

  mild::OrbParams orb;
  orb.num_features = opt.features;
  const mild::OrbExtractor extractor(orb);  // the paper's sparse-match figures are ORB's
  std::map<size_t, Frame> frames;
  auto frame = [&](size_t i) -> const Frame& {
    auto it = frames.find(i);
    if (it != frames.end()) return it->second;
    cv::Mat image = cv::imread(seq.frames[i], cv::IMREAD_GRAYSCALE);
    if (image.empty()) throw mild::InvalidInput(seq.frames[i] + ": cannot read the image");
    if (opt.scale != 1.0) cv::resize(image, image, cv::Size(), opt.scale, opt.scale, cv::INTER_LINEAR);
    const mild::Features f = extractor.extract(image);
    return frames[i] = Frame{mild::descriptorsToMat(f.descriptors), f.descriptors};
  };

  mild::SparseMatchParams sp;
  sp.num_tables = opt.num_tables;
  sp.radius = opt.radius;
  sp.max_distance = 256;  // like BFMatcher::match: every query gets its nearest
  mild::SparseMatcher sparse(sp);
  cv::BFMatcher bf(cv::NORM_HAMMING);
  cv::FlannBasedMatcher lsh(cv::makePtr<cv::flann::LshIndexParams>(24, 10, 0));

  std::vector<double> t_sparse, t_bf, t_bf_knn, t_lsh;
  Recovery rec_sparse, rec_lsh;
  size_t features = 0;
  for (const auto& [qi, ti] : pairs) {
    const Frame& q = frame(qi);
    const Frame& t = frame(ti);
    if (q.list.empty() || t.list.empty()) continue;
    features += q.list.size() + t.list.size();

    std::vector<mild::FeatureMatch> sm;
    t_sparse.push_back(fastestMs(opt.repeats, [&] { sm = sparse.match(q.list, t.list); }));
    std::vector<cv::DMatch> bm;
    t_bf.push_back(fastestMs(opt.repeats, [&] { bf.match(q.descriptors, t.descriptors, bm); }));
    std::vector<std::vector<cv::DMatch>> knn;
    std::vector<cv::DMatch> ratio_kept;
    t_bf_knn.push_back(fastestMs(opt.repeats, [&] {
      bf.knnMatch(q.descriptors, t.descriptors, knn, 2);
      ratio_kept.clear();
      for (const auto& k : knn) {
        if (k.size() == 2 && k[0].distance < 0.8f * k[1].distance) ratio_kept.push_back(k[0]);
      }
    }));
    std::vector<cv::DMatch> lm;
    // match() with a train set given rebuilds the LSH index each call: index build included.
    t_lsh.push_back(fastestMs(opt.repeats, [&] { lsh.match(q.descriptors, t.descriptors, lm); }));

    std::vector<int> s_train(q.list.size(), -1), s_dist(q.list.size(), -1), l_train(q.list.size(), -1),
        l_dist(q.list.size(), -1);
    for (const auto& m : sm) s_train[m.query] = m.train, s_dist[m.query] = m.distance;
    for (const auto& m : lm) l_train[m.queryIdx] = m.trainIdx, l_dist[m.queryIdx] = static_cast<int>(m.distance);
    rec_sparse.add(bm, s_train, s_dist, opt.valid_distance);
    rec_lsh.add(bm, l_train, l_dist, opt.valid_distance);
  }
  if (t_sparse.empty()) throw mild::InvalidInput(opt.images + ": no image pair with features to match");

  const auto s = mild::tools::summarize(t_sparse), b = mild::tools::summarize(t_bf),
             k = mild::tools::summarize(t_bf_knn), l = mild::tools::summarize(t_lsh);
  const size_t measured = t_sparse.size();
  std::printf(
      "%zu pairs (%zu loop-closing, the rest consecutive), %.0f ORB features per image (%d requested, frames "
      "scaled x%.2g), 1 thread, fastest of %d runs\n",
      measured, loop_pairs, static_cast<double>(features) / (2.0 * measured), opt.features, opt.scale, opt.repeats);
  std::printf("%-34s %10s %10s\n", "method (ms per pair)", "median", "p95");
  const std::string sparse_name =
      "sparse match (m=" + std::to_string(opt.num_tables) + ", r=" + std::to_string(opt.radius) + ")";
  std::printf("%-34s %10.3f %10.3f\n", sparse_name.c_str(), s.median, s.p95);
  std::printf("%-34s %10.3f %10.3f\n", "BFMatcher NORM_HAMMING 1-NN", b.median, b.p95);
  std::printf("%-34s %10.3f %10.3f\n", "BFMatcher k=2 + ratio 0.8", k.median, k.p95);
  std::printf("%-34s %10.3f %10.3f\n", "FLANN LSH(24,10,0) incl. build", l.median, l.p95);
  std::printf("valid pairs (BF nearest neighbour, distance < %d): %zu\n", opt.valid_distance, rec_sparse.valid);
  std::printf("recovered: sparse %.2f%%, LSH %.2f%%\n", 100 * rec_sparse.fraction(), 100 * rec_lsh.fraction());
  std::printf("headline: sparse match is %.1fx faster than brute force and %.1fx faster than LSH\n",
              b.median / s.median, l.median / s.median);
  if (opt.json) {
    const nlohmann::json out = {{"pairs", measured},
                                {"loop_pairs", loop_pairs},
                                {"features_per_image", static_cast<double>(features) / (2.0 * measured)},
                                {"sparse_ms_median", s.median},
                                {"sparse_ms_p95", s.p95},
                                {"bf_ms_median", b.median},
                                {"bf_ms_p95", b.p95},
                                {"bf_knn_ratio_ms_median", k.median},
                                {"bf_knn_ratio_ms_p95", k.p95},
                                {"lsh_ms_median", l.median},
                                {"lsh_ms_p95", l.p95},
                                {"bf_over_sparse", b.median / s.median},
                                {"lsh_over_sparse", l.median / s.median},
                                {"sparse_recovery", rec_sparse.fraction()},
                                {"lsh_recovery", rec_lsh.fraction()},
                                {"valid_pairs", rec_sparse.valid},
                                {"num_tables", opt.num_tables},
                                {"radius", opt.radius},
                                {"scale", opt.scale}};
    std::cout << out.dump() << std::endl;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Benchmark sparse match against OpenCV's BFMatcher and FLANN LSH on real image pairs."};
  app.name("mild_bench_match");
  Options opt;
  app.add_option("--images", opt.images, "image sequence (bench layout with gt_loops.txt for loop pairs)")->required();
  app.add_option("--pairs", opt.pairs, "number of image pairs (half loop-closing when ground truth exists)")
      ->check(CLI::PositiveNumber);
  app.add_option("--features", opt.features, "ORB features per image")->check(CLI::PositiveNumber);
  app.add_option("--repeats", opt.repeats, "runs per method and pair; the fastest counts")->check(CLI::PositiveNumber);
  app.add_option("--tables", opt.num_tables, "sparse match m");
  app.add_option("--radius", opt.radius, "sparse match r");
  app.add_option("--valid-distance", opt.valid_distance, "brute-force pairs closer than this count as valid");
  app.add_option("--scale", opt.scale,
                 "resize frames by this factor before extraction (small frames yield few features)")
      ->check(CLI::PositiveNumber);
  app.add_flag("--json", opt.json, "print one JSON object as the last line");
  return mild::tools::toolMain(app, argc, argv, [&] { return run(opt); });
}
