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

using Pair = std::pair<size_t, size_t>;  // query frame, train frame

// Pairs: consecutive frames, and loop-closing frames when the sequence has ground truth.
struct Pairs {
  std::vector<Pair> pairs;
  size_t loop_pairs = 0;  // the first loop_pairs of them
};

// The ground truth's loop-closing pairs, in random order; none without gt_loops.txt.
std::vector<Pair> shuffledLoopPairs(const mild::tools::ImageSequence& seq) {
  const size_t n = seq.frames.size();
  std::vector<Pair> loops;
  try {
    const mild::GroundTruth gt = mild::loadGroundTruth(seq.root + "/gt_loops.txt");
    for (const auto& [i, j] : gt.right) {
      if (static_cast<size_t>(i) < n) loops.emplace_back(i, j);
    }
  } catch (const mild::InvalidInput&) {
  }
  std::mt19937 rng(1);
  std::shuffle(loops.begin(), loops.end(), rng);
  return loops;
}

Pairs choosePairs(const Options& opt, const mild::tools::ImageSequence& seq) {
  Pairs out;
  const size_t n = seq.frames.size();
  const std::vector<Pair> loops = shuffledLoopPairs(seq);
  const size_t want = static_cast<size_t>(opt.pairs);
  out.loop_pairs = std::min(loops.size(), want / 2);
  out.pairs.assign(loops.begin(), loops.begin() + static_cast<long>(out.loop_pairs));
  const size_t consecutive = want - out.loop_pairs;
  for (size_t k = 0; k < consecutive && n > 1; ++k) {
    const size_t i = (k * (n - 1)) / std::max<size_t>(1, consecutive);
    out.pairs.emplace_back(i + 1, i);
  }
  return out;
}

// Each frame's ORB features, extracted on first use.
class FrameCache {
 public:
  FrameCache(const Options& opt, const mild::tools::ImageSequence& seq)
      : scale_(opt.scale), seq_(seq), extractor_(orbParams(opt)) {}

  const Frame& get(size_t i) {
    auto it = frames_.find(i);
    if (it != frames_.end()) return it->second;
    cv::Mat image = cv::imread(seq_.frames[i], cv::IMREAD_GRAYSCALE);
    if (image.empty()) throw mild::InvalidInput(seq_.frames[i] + ": cannot read the image");
    if (scale_ != 1.0) cv::resize(image, image, cv::Size(), scale_, scale_, cv::INTER_LINEAR);
    const mild::Features f = extractor_.extract(image);
    return frames_[i] = Frame{mild::descriptorsToMat(f.descriptors), f.descriptors};
  }

 private:
  static mild::OrbParams orbParams(const Options& opt) {
    mild::OrbParams orb;
    orb.num_features = opt.features;
    return orb;
  }

  const double scale_;
  const mild::tools::ImageSequence& seq_;
  const mild::OrbExtractor extractor_;  // the paper's sparse-match figures are ORB's
  std::map<size_t, Frame> frames_;
};

// The methods measured, built once for all pairs.
struct Matchers {
  explicit Matchers(const Options& opt) : sparse(sparseParams(opt)) {}

  static mild::SparseMatchParams sparseParams(const Options& opt) {
    mild::SparseMatchParams sp;
    sp.num_tables = opt.num_tables;
    sp.radius = opt.radius;
    sp.max_distance = 256;  // like BFMatcher::match: every query gets its nearest
    return sp;
  }

  mild::SparseMatcher sparse;
  cv::BFMatcher bf{cv::NORM_HAMMING};
  cv::FlannBasedMatcher lsh{cv::makePtr<cv::flann::LshIndexParams>(24, 10, 0)};
};

// Times per pair (ms) of each method, and how many of brute force's valid pairs sparse match and LSH found.
struct Results {
  std::vector<double> t_sparse, t_bf, t_bf_knn, t_lsh;
  Recovery rec_sparse, rec_lsh;
  size_t features = 0;
};

void measurePair(const Options& opt, const Frame& q, const Frame& t, Matchers& matchers, Results& r) {
  std::vector<mild::FeatureMatch> sm;
  r.t_sparse.push_back(fastestMs(opt.repeats, [&] { sm = matchers.sparse.match(q.list, t.list); }));
  std::vector<cv::DMatch> bm;
  r.t_bf.push_back(fastestMs(opt.repeats, [&] { matchers.bf.match(q.descriptors, t.descriptors, bm); }));
  std::vector<std::vector<cv::DMatch>> knn;
  std::vector<cv::DMatch> ratio_kept;
  r.t_bf_knn.push_back(fastestMs(opt.repeats, [&] {
    matchers.bf.knnMatch(q.descriptors, t.descriptors, knn, 2);
    ratio_kept.clear();
    for (const auto& k : knn) {
      if (k.size() == 2 && k[0].distance < 0.8f * k[1].distance) ratio_kept.push_back(k[0]);
    }
  }));
  std::vector<cv::DMatch> lm;
  // match() with a train set given rebuilds the LSH index each call: index build included.
  r.t_lsh.push_back(fastestMs(opt.repeats, [&] { matchers.lsh.match(q.descriptors, t.descriptors, lm); }));

  std::vector<int> s_train(q.list.size(), -1), s_dist(q.list.size(), -1), l_train(q.list.size(), -1),
      l_dist(q.list.size(), -1);
  for (const auto& m : sm) s_train[m.query] = m.train, s_dist[m.query] = m.distance;
  for (const auto& m : lm) l_train[m.queryIdx] = m.trainIdx, l_dist[m.queryIdx] = static_cast<int>(m.distance);
  r.rec_sparse.add(bm, s_train, s_dist, opt.valid_distance);
  r.rec_lsh.add(bm, l_train, l_dist, opt.valid_distance);
}

// Every pair whose frames both have features.
Results measurePairs(const Options& opt, const std::vector<Pair>& pairs, FrameCache& frames) {
  Matchers matchers(opt);
  Results r;
  for (const auto& [qi, ti] : pairs) {
    const Frame& q = frames.get(qi);
    const Frame& t = frames.get(ti);
    if (q.list.empty() || t.list.empty()) continue;
    r.features += q.list.size() + t.list.size();
    measurePair(opt, q, t, matchers, r);
  }
  return r;
}

struct Summaries {
  mild::tools::TimingSummary sparse, bf, bf_knn, lsh;
};

Summaries summarizeTimes(const Results& r) {
  return {mild::tools::summarize(r.t_sparse), mild::tools::summarize(r.t_bf), mild::tools::summarize(r.t_bf_knn),
          mild::tools::summarize(r.t_lsh)};
}

void printTable(const Options& opt, const Results& r, const Summaries& t, size_t loop_pairs) {
  const auto &s = t.sparse, &b = t.bf, &k = t.bf_knn, &l = t.lsh;
  const size_t measured = r.t_sparse.size();
  std::printf(
      "%zu pairs (%zu loop-closing, the rest consecutive), %.0f ORB features per image (%d requested, frames "
      "scaled x%.2g), 1 thread, fastest of %d runs\n",
      measured, loop_pairs, static_cast<double>(r.features) / (2.0 * measured), opt.features, opt.scale, opt.repeats);
  std::printf("%-34s %10s %10s\n", "method (ms per pair)", "median", "p95");
  const std::string sparse_name =
      "sparse match (m=" + std::to_string(opt.num_tables) + ", r=" + std::to_string(opt.radius) + ")";
  std::printf("%-34s %10.3f %10.3f\n", sparse_name.c_str(), s.median, s.p95);
  std::printf("%-34s %10.3f %10.3f\n", "BFMatcher NORM_HAMMING 1-NN", b.median, b.p95);
  std::printf("%-34s %10.3f %10.3f\n", "BFMatcher k=2 + ratio 0.8", k.median, k.p95);
  std::printf("%-34s %10.3f %10.3f\n", "FLANN LSH(24,10,0) incl. build", l.median, l.p95);
  std::printf("valid pairs (BF nearest neighbour, distance < %d): %zu\n", opt.valid_distance, r.rec_sparse.valid);
  std::printf("recovered: sparse %.2f%%, LSH %.2f%%\n", 100 * r.rec_sparse.fraction(), 100 * r.rec_lsh.fraction());
  std::printf("headline: sparse match is %.1fx faster than brute force and %.1fx faster than LSH\n",
              b.median / s.median, l.median / s.median);
}

void printJson(const Options& opt, const Results& r, const Summaries& t, size_t loop_pairs) {
  const auto &s = t.sparse, &b = t.bf, &k = t.bf_knn, &l = t.lsh;
  const size_t measured = r.t_sparse.size();
  const nlohmann::json out = {{"pairs", measured},
                              {"loop_pairs", loop_pairs},
                              {"features_per_image", static_cast<double>(r.features) / (2.0 * measured)},
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
                              {"sparse_recovery", r.rec_sparse.fraction()},
                              {"lsh_recovery", r.rec_lsh.fraction()},
                              {"valid_pairs", r.rec_sparse.valid},
                              {"num_tables", opt.num_tables},
                              {"radius", opt.radius},
                              {"scale", opt.scale}};
  std::cout << out.dump() << std::endl;
}

int run(const Options& opt) {
  cv::setNumThreads(1);
  const mild::tools::ImageSequence seq = mild::tools::openImageSequence(opt.images);
  const Pairs pairs = choosePairs(opt, seq);
  FrameCache frames(opt, seq);
  const Results results = measurePairs(opt, pairs.pairs, frames);
  if (results.t_sparse.empty()) throw mild::InvalidInput(opt.images + ": no image pair with features to match");

  const Summaries times = summarizeTimes(results);
  printTable(opt, results, times, pairs.loop_pairs);
  if (opt.json) printJson(opt, results, times, pairs.loop_pairs);
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
