// mild_analysis: the MIH accuracy/complexity analysis (seed paper III.B) as a table, a parameter
// advisor, a plot, and a measurement of Hamming-distance priors on an image sequence.

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>

#include <unistd.h>

#include <CLI/CLI.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include "common/tool_main.hpp"

#include "common/image_sequence.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/offline/distance_priors.hpp"
#include "mild_lcd/offline/evaluation.hpp"
#include "mild_lcd/offline/mih_analysis.hpp"
#include "offline_plots.hpp"

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

struct Options {
  std::string model = "exact";
  double inlier_mean = 32, inlier_std = 10, outlier_mean = 128, outlier_std = 20;
  std::string priors;
  std::string m_range = "4:32";
  std::string r_range = "0:3";
  bool recommend = false;
  double min_accuracy = 0.8;
  bool online = false, offline = false;
  double database_features = 800000;
  std::string plot;
  std::string measure_priors;
  std::string output;
  int pairs = 150;
  std::string features = "orb";
  int bits = 256;
  bool json = false;
};

std::pair<int, int> parseRange(const std::string& text, const char* what) {
  const auto number = [&](const std::string& part) {
    size_t used = 0;
    const int v = std::stoi(part, &used);
    if (used != part.size()) throw std::invalid_argument(part);
    return v;
  };
  try {
    const auto colon = text.find(':');
    if (colon == std::string::npos) return {number(text), number(text)};
    return {number(text.substr(0, colon)), number(text.substr(colon + 1))};
  } catch (const std::exception&) {
    throw mild::InvalidInput(std::string(what) + " must be FIRST:LAST, e.g. 4:32, got '" + text + "'");
  }
}

json costJson(const mild::MihCost& c) {
  return {{"m", c.m},          {"r", c.r}, {"R", c.accuracy}, {"E", c.complexity}, {"E_fixed", c.fixed_cost},
          {"probes", c.probes}};
}

json histogramJson(const std::vector<double>& counts) {
  json out = json::array();
  for (double c : counts) out.push_back(c);
  return out;
}

std::pair<mild::DistancePrior, mild::DistancePrior> loadPriors(const Options& opt) {
  if (opt.priors.empty()) {
    return {mild::DistancePrior::normal(opt.inlier_mean, opt.inlier_std, opt.bits),
            mild::DistancePrior::normal(opt.outlier_mean, opt.outlier_std, opt.bits)};
  }
  std::ifstream in(opt.priors);
  if (!in) throw mild::InvalidInput(opt.priors + ": cannot read the priors file");
  json j;
  try {
    in >> j;
    const int bits = j.value("bits", 256);  // files from before the width was recorded are ORB's
    return {mild::DistancePrior::fromCounts(j.at("inlier_counts").get<std::vector<double>>(), bits),
            mild::DistancePrior::fromCounts(j.at("outlier_counts").get<std::vector<double>>(), bits)};
  } catch (const json::exception& e) {
    throw mild::InvalidInput(opt.priors + ": not a priors file written by --measure-priors (" + e.what() + ")");
  }
}

// Overlapping pairs: ground-truth true pairs; disjoint pairs: frames at least 40 apart that the
// ground truth does not list at all. Both subsampled evenly to `count` pairs, reproducibly.
int measurePriors(const Options& opt) {
  const mild::tools::ImageSequence seq = mild::tools::openImageSequence(opt.measure_priors);
  const mild::GroundTruth truth = mild::loadGroundTruth((fs::path(seq.root) / "gt_loops.txt").string());
  std::set<std::pair<int, int>> listed(truth.right.begin(), truth.right.end());
  listed.insert(truth.dont_care.begin(), truth.dont_care.end());
  const int n = static_cast<int>(seq.frames.size());

  std::vector<std::pair<int, int>> overlapping(truth.right.begin(), truth.right.end()), disjoint;
  std::mt19937_64 rng(1);
  std::uniform_int_distribution<int> frame(0, n - 1);
  for (int attempts = 0; disjoint.size() < static_cast<size_t>(opt.pairs) && attempts < 100 * opt.pairs; ++attempts) {
    int i = frame(rng), j = frame(rng);
    if (i < j) std::swap(i, j);
    if (i - j >= 40 && !listed.count({i, j})) disjoint.emplace_back(i, j);
  }
  std::shuffle(overlapping.begin(), overlapping.end(), rng);
  if (overlapping.size() > static_cast<size_t>(opt.pairs)) overlapping.resize(opt.pairs);

  mild::FeatureParams feature_params;
  feature_params.type = opt.features;
  const std::unique_ptr<mild::FeatureExtractor> extractor = mild::makeFeatureExtractor(feature_params);
  std::map<int, mild::Features> features;
  auto featuresOf = [&](int i) -> const mild::Features* {
    auto it = features.find(i);
    if (it == features.end()) {
      const cv::Mat image = cv::imread(seq.frames.at(i), cv::IMREAD_GRAYSCALE);
      if (image.empty()) throw mild::InvalidInput(seq.frames[i] + ": cannot read the image");
      it = features.emplace(i, extractor->extract(image, mild::PixelFormat::kGray)).first;
    }
    return &it->second;
  };
  std::vector<mild::FeaturePair> a, b;
  for (auto [i, j] : overlapping) a.push_back({featuresOf(i), featuresOf(j)});
  for (auto [i, j] : disjoint) b.push_back({featuresOf(i), featuresOf(j)});
  const mild::MeasuredPriors measured = mild::measureDistancePriors(a, b);
  const mild::DistancePrior inliers = measured.inliers(), outliers = measured.outliers();

  const int bits = measured.bits;
  json out = {{"sequence", seq.root},
              {"features", opt.features},
              {"bits", bits},
              {"overlapping_pairs", overlapping.size()},
              {"overlapping_pairs_used", measured.overlapping_pairs_used},
              {"disjoint_pairs", disjoint.size()},
              {"inliers", measured.inlier_descriptors.size()},
              {"inlier_mean", inliers.mean()},
              {"outlier_mean", outliers.mean()},
              {"inlier_counts", histogramJson(measured.inlier_counts)},
              {"outlier_counts", histogramJson(measured.outlier_counts)}};
  // How well R(r, m), computed from these priors, predicts what the real index finds.
  json validation = json::array();
  // The same tables per bit for any width: (16, 0) for ORB is (32, 0) for BRISK.
  const int scale = std::max(1, bits / 256);
  for (auto [m, r] : std::vector<std::pair<int, int>>{{16, 0}, {12, 0}, {22, 0}, {11, 1}, {16, 1}, {8, 2}}) {
    m *= scale;
    mild::MihParams params;
    params.num_tables = m;
    params.radius = r;
    validation.push_back({{"m", m},
                          {"r", r},
                          {"index_found", mild::indexRecall(measured.inlier_descriptors, params)},
                          {"R_exact", mild::analyse(r, m, inliers, outliers, mild::BitModel::kExact).accuracy},
                          {"R_paper", mild::analyse(r, m, inliers, outliers, mild::BitModel::kPaper).accuracy}});
  }
  out["validation"] = validation;
  if (!opt.output.empty()) {
    std::ofstream file(opt.output);
    file << out.dump(1) << "\n";
    if (!file) throw mild::InvalidInput(opt.output + ": cannot write the priors file");
  }
  auto stddev = [](const mild::DistancePrior& p) {
    double mean = p.mean(), var = 0.0;
    for (size_t d = 0; d < p.p.size(); ++d) var += p.p[d] * (d - mean) * (d - mean);
    return std::sqrt(var);
  };
  if (opt.json) {
    json summary = out;
    summary["inlier_std"] = stddev(inliers);
    summary["outlier_std"] = stddev(outliers);
    std::cout << summary.dump() << "\n";
  } else {
    std::printf("%zu inlier correspondences from %zu of %zu overlapping pairs; %zu disjoint pairs\n",
                measured.inlier_descriptors.size(), measured.overlapping_pairs_used, overlapping.size(),
                disjoint.size());
    std::printf("%s, %d-bit descriptors\n", opt.features.c_str(), bits);
    std::printf("inliers:  mean %.1f, std %.1f bits   (paper, ORB: N(32, 10))\n", inliers.mean(), stddev(inliers));
    std::printf("outliers: mean %.1f, std %.1f bits   (paper, ORB: N(128, 20))\n", outliers.mean(), stddev(outliers));
    std::printf("inlier pairs the index finds, against R(r, m) from these priors:\n");
    for (const auto& v : validation) {
      std::printf("  (m, r) = (%2d, %d): index %.3f   R exact model %.3f   R paper model %.3f\n", v["m"].get<int>(),
                  v["r"].get<int>(), v["index_found"].get<double>(), v["R_exact"].get<double>(),
                  v["R_paper"].get<double>());
    }
    if (!opt.output.empty()) std::printf("priors written to %s (use with --priors)\n", opt.output.c_str());
  }
  return 0;
}

int run(const Options& opt) {
  if (!opt.measure_priors.empty()) return measurePriors(opt);
  if (opt.online && opt.offline) throw mild::InvalidInput("--online and --offline exclude each other");
  const mild::BitModel model = mild::bitModelFromName(opt.model);
  const auto [m_min, m_max] = parseRange(opt.m_range, "--m-range");
  const auto [r_min, r_max] = parseRange(opt.r_range, "--r-range");
  if (m_min < 2 || m_max > 64 || r_min < 0 || r_max > 4) {
    throw mild::InvalidInput("--m-range must lie in 2:64 and --r-range in 0:4");
  }
  const auto [inliers, outliers] = loadPriors(opt);
  const std::vector<mild::MihCost> grid = mild::analyseGrid(m_min, m_max, r_min, r_max, inliers, outliers, model);

  if (!opt.plot.empty()) {
    json data = {{"model", opt.model}, {"min_accuracy", opt.min_accuracy}, {"rows", json::array()}};
    for (const auto& c : grid) data["rows"].push_back(costJson(c));
    const fs::path data_path = fs::temp_directory_path() / ("mild_analysis_" + std::to_string(::getpid()) + ".json");
    std::ofstream(data_path) << data.dump();
    const std::string command = "/usr/bin/python3 '" + mild::tools::findScript("plot_analysis.py") + "' '" +
                                data_path.string() + "' '" + opt.plot + "'";
    const int status = std::system(command.c_str());
    fs::remove(data_path);
    if (status != 0) throw mild::InvalidInput("plotting failed: " + command);
  }

  if (opt.recommend) {
    const bool online = !opt.offline;  // online unless asked otherwise: mild_lcd builds its tables live
    const mild::Recommendation rec = mild::recommend(grid, opt.min_accuracy, online, opt.database_features);
    if (opt.json) {
      json out = {
          {"model", opt.model},           {"min_accuracy", opt.min_accuracy}, {"mode", online ? "online" : "offline"},
          {"recommended", json::array()}, {"choice", costJson(rec.choice)},   {"explanation", rec.explanation}};
      for (const auto& c : rec.candidates) out["recommended"].push_back(costJson(c));
      std::cout << out.dump() << "\n";
    } else {
      std::printf("model %s, accuracy >= %.3f; smallest m per r:\n", opt.model.c_str(), opt.min_accuracy);
      for (const auto& c : rec.candidates) {
        std::printf("  (m, r) = (%2d, %d)  R = %.4f  E = %.3g  E_fixed = %.3g\n", c.m, c.r, c.accuracy, c.complexity,
                    c.fixed_cost);
      }
      std::printf("%s\n", rec.explanation.c_str());
    }
    return 0;
  }

  if (opt.json) {
    json out = {{"model", opt.model}, {"rows", json::array()}};
    for (const auto& c : grid) out["rows"].push_back(costJson(c));
    std::cout << out.dump() << "\n";
  } else {
    std::printf("model %s; inlier prior mean %.1f, outlier prior mean %.1f bits\n", opt.model.c_str(), inliers.mean(),
                outliers.mean());
    std::printf(" r   m   R(accuracy)  E(complexity)  E_fixed     probes\n");
    for (const auto& c : grid) {
      std::printf("%2d  %2d   %.4f       %.4e     %.3e   %.0f\n", c.r, c.m, c.accuracy, c.complexity, c.fixed_cost,
                  c.probes);
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"MIH analysis: P_recall(r, m, d), accuracy R, complexity E, fixed cost E_fixed; advisor; priors."};
  app.name("mild_analysis");
  Options opt;
  app.add_option("--model", opt.model,
                 "where differing bits fall: paper (balls in bins) or exact (distinct bit positions)")
      ->capture_default_str();
  app.add_option("--inlier-mean", opt.inlier_mean, "inlier Hamming distance mean")->capture_default_str();
  app.add_option("--inlier-std", opt.inlier_std, "inlier standard deviation")->capture_default_str();
  app.add_option("--outlier-mean", opt.outlier_mean, "outlier Hamming distance mean")->capture_default_str();
  app.add_option("--outlier-std", opt.outlier_std, "outlier standard deviation")->capture_default_str();
  app.add_option("--priors", opt.priors, "measured priors (JSON from --measure-priors) instead of the normal ones");
  app.add_option("--m-range", opt.m_range, "hash tables FIRST:LAST (2..64)")->capture_default_str();
  app.add_option("--r-range", opt.r_range, "probe radii FIRST:LAST (0..4)")->capture_default_str();
  app.add_flag("--recommend", opt.recommend,
               "recommend (m, r): for each r the smallest m reaching --min-accuracy, "
               "and the cheapest of those");
  app.add_option("--min-accuracy", opt.min_accuracy, "accuracy R to reach")->capture_default_str();
  app.add_flag("--online", opt.online, "cost = E * database features + E_fixed (the default)");
  app.add_flag("--offline", opt.offline, "cost = E (tables built once)");
  app.add_option("--database-features", opt.database_features, "stored features, for the online cost")
      ->capture_default_str();
  app.add_option("--plot", opt.plot, "PNG of accuracy against complexity for each r");
  app.add_option("--measure-priors", opt.measure_priors, "measure the priors on a sequence in the bench layout");
  app.add_option("--output", opt.output, "with --measure-priors: JSON file for --priors");
  app.add_option("--pairs", opt.pairs, "with --measure-priors: overlapping and disjoint pairs to use")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--features", opt.features, "with --measure-priors: the extractor (orb, brisk, akaze)")
      ->capture_default_str();
  app.add_option("--bits", opt.bits, "descriptor width of the normal priors (256 ORB, 512 BRISK, 488 AKAZE)")
      ->check(CLI::Range(64, 512))
      ->capture_default_str();
  app.add_flag("--json", opt.json, "print one JSON object as the last line");
  return mild::tools::toolMain(app, argc, argv, [&] { return run(opt); });
}
