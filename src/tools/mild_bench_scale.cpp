// mild_bench_scale: query cost of the keyframe database from 1,000 to 100,000 keyframes of 800
// real ORB features, one thread. Per size, in one run: mild_lcd's MIH with and without early
// termination, our reproduction of the original MILD (2017) index design, faiss's multi-index
// hashing (IndexBinaryMultiHash) and exact search (IndexBinaryFlat), and mild_lcd's own exact
// brute force where these finish in reasonable time; memory per stored feature and insert time.
// Speed-ups are ratios within the run.

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <numeric>
#include <optional>
#include <sstream>

#include <CLI/CLI.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include "common/tool_main.hpp"

#if MILD_HAVE_FAISS
#include "bench/faiss_baselines.hpp"
#endif
#include "bench/mild2017_index.hpp"
#include "bench/sequence_keyframes.hpp"
#include "bench/synthetic_keyframes.hpp"
#include "common/image_sequence.hpp"
#include "common/timing_summary.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stopwatch.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "mild_lcd/place/keyframe_database.hpp"

namespace fs = std::filesystem;
using json = nlohmann::json;
using mild::Clock;
using mild::msSince;

namespace {

struct Options {
  std::string sizes = "1000,5000,10000,50000,100000";
  std::vector<std::string> images;
  std::string sequence;
  int features = 800;
  std::string feature_type = "orb";
  int queries = 30;
  int brute_queries = 3;
  size_t brute_max_keyframes = 10000;
  size_t faiss_max_keyframes = 10000;
  int faiss_exact_queries = 1;
  bool skip_baseline = false;
  size_t persistence_keyframes = 5000;
  uint32_t bounded = mild::MihParams{}.max_bucket_entries;  // the shipped bound
  bool inline_prefixes = true;
  uint32_t max_candidates = mild::MihParams{}.max_candidates_per_feature;  // the shipped query budget
  bool json = false;
};

std::vector<size_t> parseSizes(const std::string& text) {
  std::vector<size_t> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    try {
      size_t used = 0;
      const long v = std::stol(item, &used);
      if (used != item.size() || v < 1) throw std::invalid_argument(item);
      out.push_back(static_cast<size_t>(v));
    } catch (const std::exception&) {
      throw mild::InvalidInput("--sizes must be a comma-separated list of keyframe counts, got '" + text + "'");
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::string> defaultImageDirs() {
  const fs::path bench = fs::path(MILD_SOURCE_DIR) / ".." / "shared" / "bench";
  std::vector<std::string> dirs;
  for (const char* s : {"pub_corridor", "pub_city", "pub_aliasing"}) {
    if (fs::is_directory(bench / s)) dirs.push_back((bench / s).string());
  }
  if (dirs.empty()) dirs.push_back((fs::path(MILD_SOURCE_DIR) / "sample" / "corridor").string());
  return dirs;
}

size_t availableMemoryBytes() {
  return static_cast<size_t>(sysconf(_SC_AVPHYS_PAGES)) * static_cast<size_t>(sysconf(_SC_PAGE_SIZE));
}

struct Timing {
  std::vector<double> samples;
  double median() const { return mild::tools::summarize(samples).median; }
  double p95() const { return mild::tools::summarize(samples).p95; }
};

json nullable(std::optional<double> v) { return v ? json(*v) : json(nullptr); }

using KeyframeAt = std::function<mild::DescriptorList(size_t)>;

// Insert time, the keyframes' generation left out: the mean over the whole build, the mean over its
// last tenth (what one insert costs at this size), the slowest single insert (a merge, or a
// growing array), the 99th percentile and how many inserts took over 2 ms (issue 16's bound).
struct InsertTiming {
  double mean_ms = 0.0;
  double last_tenth_ms = 0.0;
  double max_ms = 0.0;
  double p99_ms = 0.0;
  size_t over_2ms = 0;
};

template <class Database>
InsertTiming insertAll(Database& db, const KeyframeAt& keyframe_at, size_t n) {
  std::vector<double> samples;
  samples.reserve(n);
  for (size_t k = 0; k < n; ++k) {
    const mild::DescriptorList keyframe = keyframe_at(k);
    const auto start = Clock::now();
    db.insert(keyframe);
    samples.push_back(msSince(start));
  }
  InsertTiming timing;
  if (n == 0) return timing;
  const size_t tail = std::max<size_t>(1, n / 10);
  for (size_t k = 0; k < n; ++k) {
    timing.mean_ms += samples[k] / static_cast<double>(n);
    if (k >= n - tail) timing.last_tenth_ms += samples[k] / static_cast<double>(tail);
    timing.max_ms = std::max(timing.max_ms, samples[k]);
    if (samples[k] > 2.0) ++timing.over_2ms;
  }
  std::sort(samples.begin(), samples.end());
  timing.p99_ms = samples[std::min(n - 1, n * 99 / 100)];
  return timing;
}

// Save and load times of a detector holding n keyframes (with keypoints, as a real one).
json measurePersistence(const KeyframeAt& keyframe_at, size_t n) {
  mild::DetectorState state;
  state.next_id = n;
  for (size_t k = 0; k < n; ++k) {
    state.descriptors.push_back(keyframe_at(k));
    mild::KeyframeRecord record;
    record.id = k;
    record.stamp = 0.1 * static_cast<double>(k);
    for (size_t i = 0; i < state.descriptors.back().size(); ++i) {
      record.keypoints.emplace_back(static_cast<float>(i % 320), static_cast<float>(i / 320), 31.0f, 90.0f, 1e-3f, 0);
    }
    state.records.push_back(std::move(record));
  }
  mild::DetectorParams params;
  params.verification.enabled = false;
  params.features.descriptor_bytes = state.descriptors.front().front().bytes;
  mild::LoopDetector detector(params);
  detector.restore(std::move(state), false);
  const fs::path file = fs::temp_directory_path() / ("mild_bench_scale_" + std::to_string(::getpid()) + ".mild");
  auto t = Clock::now();
  mild::saveDetector(detector, file.string());
  const double save_s = msSince(t) / 1000.0;
  mild::LoopDetector loaded(params);
  t = Clock::now();
  const mild::LoadReport report = mild::loadDetector(loaded, file.string(), true);
  const double load_s = msSince(t) / 1000.0;
  const double file_mb = static_cast<double>(fs::file_size(file)) / 1e6;
  fs::remove(file);
  return {
      {"keyframes", n}, {"features", report.features}, {"file_mb", file_mb}, {"save_s", save_s}, {"load_s", load_s}};
}

int run(const Options& opt) {
#if !MILD_HAVE_FAISS
  // faiss (Debian's libfaiss-dev, with OpenMP) is this benchmark's only use of it, and optional.
  if (opt.faiss_max_keyframes > 0) {
    std::cerr << "note: built without faiss (MILD_WITH_FAISS=OFF or libfaiss-dev not found): the faiss columns are "
                 "skipped (null)\n";
  }
#endif
  cv::setNumThreads(1);
  const std::vector<std::string> dirs = opt.images.empty() ? defaultImageDirs() : opt.images;

  mild::FeatureParams feature_params;
  feature_params.type = opt.feature_type;
  feature_params.orb.num_features = feature_params.brisk.num_features = feature_params.akaze.num_features =
      opt.features;
  const std::unique_ptr<mild::FeatureExtractor> extractor_owner = mild::makeFeatureExtractor(feature_params);
  const mild::FeatureExtractor& extractor = *extractor_owner;
  // Keyframes: a real walk's frames (--sequence), or real frames replicated to any size.
  std::optional<mild::tools::SequenceKeyframes> walk;
  std::optional<mild::tools::SyntheticKeyframes> synthetic;
  std::vector<mild::DescriptorList> queries;
  KeyframeAt keyframe_at;
  std::vector<size_t> sizes = parseSizes(opt.sizes);
  if (!opt.sequence.empty()) {
    walk.emplace(opt.sequence, extractor, opt.queries);
    queries = walk->queries();
    keyframe_at = [&walk](size_t k) { return walk->keyframe(k); };
    // Prefixes of the walk, and the whole walk.
    sizes.erase(std::remove_if(sizes.begin(), sizes.end(), [&](size_t n) { return n >= walk->size(); }), sizes.end());
    sizes.push_back(walk->size());
    if (!opt.json) {
      std::printf("walk %s: %zu stored keyframes, %zu held-out queries; up to %d features per keyframe; one thread\n",
                  opt.sequence.c_str(), walk->size(), queries.size(), opt.features);
    }
  } else {
    std::vector<mild::DescriptorList> real;
    for (const auto& dir : dirs) {
      for (const auto& path : mild::tools::openImageSequence(dir).frames) {
        const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (!image.empty()) real.push_back(extractor.extract(image, mild::PixelFormat::kGray).descriptors);
      }
    }
    synthetic.emplace(std::move(real), static_cast<size_t>(opt.features));
    for (int q = 0; q < opt.queries; ++q) queries.push_back(synthetic->query(q));
    keyframe_at = [&synthetic](size_t k) { return synthetic->keyframe(k); };
    if (!opt.json) {
      std::printf("%zu real frames from %zu sequence(s); %d features per keyframe; %d queries per size; one thread\n",
                  synthetic->realFrames(), dirs.size(), opt.features, opt.queries);
    }
  }

  // The MIH columns are the index without the bound on bucket length or the query budget (early
  // termination at 20 of the first 64 bits as shipped); the bounded column adds both, and with the
  // shipped values it is the shipped configuration (config/default.yaml).
  mild::DatabaseParams et_params;
  et_params.descriptor_bytes = extractor.descriptorBytes();
  et_params.index.max_bucket_entries = 0;  // the index unbounded: every bucket whole, every entry read
  et_params.index.max_candidates_per_feature = 0;
  const uint32_t shipped_bound = mild::MihParams{}.max_bucket_entries;
  const int bits = et_params.descriptor_bytes * 8;
  mild::DatabaseParams full_params = et_params;
  full_params.similarity.early_termination_threshold = 64;  // never rejects early

  json rows = json::array();
  if (!opt.json) {
    std::printf("%9s %11s %11s %12s %12s %12s %10s %9s %9s %9s\n", "keyframes", "mih_ms", "mih_et_ms", "mih_et_p95",
                "mild2017_ms", "brute_ms", "B/feature", "insert_ms", "x2017", "xbrute");
  }
  for (size_t n : sizes) {
    size_t features = n * static_cast<size_t>(opt.features);
    if (walk) {
      features = 0;
      for (size_t k = 0; k < n; ++k) features += walk->keyframe(k).size();
    }
    // mild_lcd needs ~100 bytes per feature (~230 with inline prefixes), the 2017 design ~170; one after the other.
    const size_t bytes_needed = features * (opt.inline_prefixes ? 260 : 200);
    if (bytes_needed > availableMemoryBytes()) {
      if (!opt.json)
        std::printf("%9zu skipped: needs about %.1f GB, %.1f GB available\n", n, bytes_needed / 1e9,
                    availableMemoryBytes() / 1e9);
      rows.push_back({{"keyframes", n}, {"skipped", "memory"}});
      continue;
    }
    json row = {{"keyframes", n}};
    Timing mih, mih_et, baseline, brute, faiss_mih, faiss_exact;
    double faiss_bytes_per_feature = 0.0;
    size_t faiss_mih_pairs = 0, faiss_exact_pairs = 0;  // of the first query, a check on both
    // Pairs (query feature, stored feature) within d0 found per query: what votes. Against the
    // exact range search of the first faiss_exact_queries queries, each index's recall of them.
    std::vector<uint64_t> unbounded_pairs, bounded_pairs, faiss_pairs, exact_pairs;
    mild::QueryStats work;
    InsertTiming insert;
    double bytes_per_feature = 0.0;
    {
      mild::KeyframeDatabase db(et_params);
      insert = insertAll(db, keyframe_at, n);
      bytes_per_feature = static_cast<double>(db.memoryBytes()) / static_cast<double>(db.featureCount());
      for (const auto& q : queries) {
        auto t = Clock::now();
        const auto r = db.query(q);
        mih_et.samples.push_back(msSince(t));
        work += r.stats;
        unbounded_pairs.push_back(r.stats.votes);
      }
      // Without early termination: the same index, queried with the threshold at 64.
      db.setSimilarityParams(full_params.similarity);
      for (const auto& q : queries) {
        auto t = Clock::now();
        const auto r = db.query(q);
        mih.samples.push_back(msSince(t));
        (void)r;
      }
      if (n <= opt.brute_max_keyframes) {
        for (int q = 0; q < std::min<int>(opt.brute_queries, static_cast<int>(queries.size())); ++q) {
          auto t = Clock::now();
          const auto r = db.query(queries[q], mild::kAllKeyframes, mild::SearchMode::kExact);
          brute.samples.push_back(msSince(t));
          (void)r;
        }
      }
    }
    Timing inlined;
    double inline_insert_ms = 0.0, inline_bytes_per_feature = 0.0;
    if (opt.inline_prefixes) {  // the same index with each entry's first 64 bits beside its id
      mild::DatabaseParams inline_params = et_params;
      inline_params.index.inline_prefixes = true;
      mild::KeyframeDatabase db(inline_params);
      inline_insert_ms = insertAll(db, keyframe_at, n).mean_ms;
      inline_bytes_per_feature = static_cast<double>(db.memoryBytes()) / static_cast<double>(db.featureCount());
      for (const auto& q : queries) {
        auto t = Clock::now();
        const auto r = db.query(q);
        inlined.samples.push_back(msSince(t));
        (void)r;
      }
    }
    Timing bounded;
    mild::QueryStats bounded_work;
    InsertTiming bounded_insert;
    double bounded_bytes_per_feature = 0.0;
    if (opt.bounded > 0) {  // the same, with max_bucket_entries: query time bounded as the map grows
      mild::DatabaseParams bounded_params = et_params;
      bounded_params.index.max_bucket_entries = opt.bounded;
      bounded_params.index.max_candidates_per_feature = opt.max_candidates;
      mild::KeyframeDatabase db(bounded_params);
      bounded_insert = insertAll(db, keyframe_at, n);
      bounded_bytes_per_feature = static_cast<double>(db.memoryBytes()) / static_cast<double>(db.featureCount());
      for (const auto& q : queries) {
        auto t = Clock::now();
        const auto r = db.query(q);
        bounded.samples.push_back(msSince(t));
        bounded_work += r.stats;
        bounded_pairs.push_back(r.stats.votes);
      }
    }
    // The shipped configuration's figures: the bounded database when its bound is the shipped one.
    const bool shipped_measured = opt.max_candidates == mild::MihParams{}.max_candidates_per_feature &&
                                  (shipped_bound == 0 || (opt.bounded == shipped_bound && !bounded.samples.empty()));
    const Timing& shipped = shipped_bound == 0 ? mih_et : bounded;
    const mild::QueryStats& shipped_work = shipped_bound == 0 ? work : bounded_work;
    const InsertTiming& shipped_insert = shipped_bound == 0 ? insert : bounded_insert;
    const double shipped_bytes = shipped_bound == 0 ? bytes_per_feature : bounded_bytes_per_feature;
#if MILD_HAVE_FAISS
    if (n <= opt.faiss_max_keyframes) {  // faiss, on the same descriptors, range search within d0
      mild::tools::FaissBaselines faiss(bits, et_params.index.tablesFor(bits));
      for (size_t k = 0; k < n; ++k) faiss.add(keyframe_at(k));
      faiss_bytes_per_feature = faiss.entryBytesPerFeature();
      const int d0 = et_params.similarity.scaledTo(bits).max_distance;
      for (const auto& q : queries) {
        auto t = Clock::now();
        const size_t found = faiss.queryMultiHash(q, d0);
        faiss_mih.samples.push_back(msSince(t));
        if (&q == &queries.front()) faiss_mih_pairs = found;
        faiss_pairs.push_back(found);
      }
      for (int q = 0; q < std::min<int>(opt.faiss_exact_queries, static_cast<int>(queries.size())); ++q) {
        auto t = Clock::now();
        const size_t found = faiss.queryExact(queries[q], d0);
        faiss_exact.samples.push_back(msSince(t));
        if (q == 0) faiss_exact_pairs = found;
        exact_pairs.push_back(found);
      }
    }
#endif

    if (!opt.skip_baseline && bits == 256) {  // the 2017 design is ORB's 16 tables of 16 bits
      mild::tools::Mild2017Index old(et_params);
      for (size_t k = 0; k < n; ++k) old.insert(keyframe_at(k));
      for (const auto& q : queries) {
        auto t = Clock::now();
        const auto r = old.query(q);
        baseline.samples.push_back(msSince(t));
        (void)r;
      }
    }
    const std::optional<double> brute_ms = brute.samples.empty() ? std::nullopt : std::optional<double>(brute.median());
    const std::optional<double> base_ms =
        baseline.samples.empty() ? std::nullopt : std::optional<double>(baseline.median());
    row["mih_ms_median"] = mih.median();
    row["mih_ms_p95"] = mih.p95();
    row["mih_et_ms_median"] = mih_et.median();
    row["mih_et_ms_p95"] = mih_et.p95();
    row["mih_bounded_ms_median"] = bounded.samples.empty() ? json(nullptr) : json(bounded.median());
    row["mih_bounded_ms_p95"] = bounded.samples.empty() ? json(nullptr) : json(bounded.p95());
    row["bound"] = opt.bounded;
    row["query_budget"] = opt.max_candidates;
    // The shipped configuration (config/default.yaml): early termination, buckets bounded at
    // index/max_bucket_entries, prefixes not inlined.
    row["default_ms_median"] = shipped_measured ? json(shipped.median()) : json(nullptr);
    row["default_ms_p95"] = shipped_measured ? json(shipped.p95()) : json(nullptr);
    row["default_bytes_per_feature"] = shipped_measured ? json(shipped_bytes) : json(nullptr);
    row["default_insert_ms_last_tenth"] = shipped_measured ? json(shipped_insert.last_tenth_ms) : json(nullptr);
    row["default_insert_ms_max"] = shipped_measured ? json(shipped_insert.max_ms) : json(nullptr);
    row["default_insert_ms_p99"] = shipped_measured ? json(shipped_insert.p99_ms) : json(nullptr);
    row["default_inserts_over_2ms"] = shipped_measured ? json(shipped_insert.over_2ms) : json(nullptr);
    row["default_candidates_per_query_feature"] =
        shipped_measured ? json(static_cast<double>(shipped_work.candidates_visited) / shipped_work.query_features)
                         : json(nullptr);
    row["mih_inline_ms_median"] = inlined.samples.empty() ? json(nullptr) : json(inlined.median());
    row["mih_inline_ms_p95"] = inlined.samples.empty() ? json(nullptr) : json(inlined.p95());
    row["inline_bytes_per_feature"] = inlined.samples.empty() ? json(nullptr) : json(inline_bytes_per_feature);
    row["inline_insert_ms"] = inlined.samples.empty() ? json(nullptr) : json(inline_insert_ms);
    row["baseline_2017_ms_median"] = nullable(base_ms);
    row["baseline_2017_ms_p95"] = base_ms ? json(baseline.p95()) : json(nullptr);
    row["brute_ms_median"] = nullable(brute_ms);
    const std::optional<double> faiss_mih_ms =
        faiss_mih.samples.empty() ? std::nullopt : std::optional<double>(faiss_mih.median());
    const std::optional<double> faiss_exact_ms =
        faiss_exact.samples.empty() ? std::nullopt : std::optional<double>(faiss_exact.median());
    row["faiss_mih_ms_median"] = nullable(faiss_mih_ms);
    row["faiss_multihash_ms_median"] = nullable(faiss_mih_ms);  // the name issue 16 asks for
    row["faiss_mih_ms_p95"] = faiss_mih_ms ? json(faiss_mih.p95()) : json(nullptr);
    row["faiss_exact_ms_median"] = nullable(faiss_exact_ms);
    row["faiss_mih_pairs_first_query"] = faiss_mih_ms ? json(faiss_mih_pairs) : json(nullptr);
    row["faiss_exact_pairs_first_query"] = faiss_exact_ms ? json(faiss_exact_pairs) : json(nullptr);
    row["faiss_mih_bytes_per_feature"] = faiss_mih_ms ? json(faiss_bytes_per_feature) : json(nullptr);
    row["speedup_vs_faiss_mih"] = faiss_mih_ms ? json(*faiss_mih_ms / mih_et.median()) : json(nullptr);
    row["speedup_vs_faiss_exact"] = faiss_exact_ms ? json(*faiss_exact_ms / mih_et.median()) : json(nullptr);
    const auto pair_recall = [&exact_pairs](const std::vector<uint64_t>& found) -> std::optional<double> {
      const size_t n_queries = exact_pairs.size();
      if (n_queries == 0 || found.size() < n_queries) return std::nullopt;
      const double truth = std::accumulate(exact_pairs.begin(), exact_pairs.end(), 0.0);
      return truth > 0 ? std::optional<double>(std::accumulate(found.begin(), found.begin() + n_queries, 0.0) / truth)
                       : std::nullopt;
    };
    const std::optional<double> recall_default = pair_recall(shipped_bound == 0 ? unbounded_pairs : bounded_pairs);
    const std::optional<double> recall_unbounded = pair_recall(unbounded_pairs);
    const std::optional<double> recall_faiss = pair_recall(faiss_pairs);
    row["pair_recall_queries"] = exact_pairs.size();
    row["pair_recall_default"] = shipped_measured ? nullable(recall_default) : json(nullptr);
    row["pair_recall_unbounded"] = nullable(recall_unbounded);
    row["pair_recall_faiss_multihash"] = nullable(recall_faiss);
    row["bytes_per_feature"] = bytes_per_feature;
    row["candidates_per_query_feature"] = static_cast<double>(work.candidates_visited) / work.query_features;
    row["full_distances_per_query_feature"] = static_cast<double>(work.full_distances) / work.query_features;
    row["votes_per_query_feature"] = static_cast<double>(work.votes) / work.query_features;
    row["insert_ms_per_keyframe"] = insert.mean_ms;
    row["insert_ms_last_tenth"] = insert.last_tenth_ms;
    row["insert_ms_max"] = insert.max_ms;
    row["insert_ms_p99"] = insert.p99_ms;
    row["inserts_over_2ms"] = insert.over_2ms;
    row["speedup_vs_2017"] = base_ms ? json(*base_ms / mih_et.median()) : json(nullptr);
    row["speedup_vs_brute"] = brute_ms ? json(*brute_ms / mih_et.median()) : json(nullptr);
    rows.push_back(row);
    if (!opt.json) {
      auto cell = [](std::optional<double> v, const char* fmt) {
        char buf[32];
        if (!v) return std::string("-");
        std::snprintf(buf, sizeof(buf), fmt, *v);
        return std::string(buf);
      };
      std::printf("%9zu %11.2f %11.2f %12.2f %12s %12s %10.1f %9.2f %9s %9s\n", n, mih.median(), mih_et.median(),
                  mih_et.p95(), cell(base_ms, "%.2f").c_str(), cell(brute_ms, "%.1f").c_str(), bytes_per_feature,
                  insert.mean_ms,
                  cell(base_ms ? std::optional<double>(*base_ms / mih_et.median()) : std::nullopt, "%.1fx").c_str(),
                  cell(brute_ms ? std::optional<double>(*brute_ms / mih_et.median()) : std::nullopt, "%.0fx").c_str());
      if (faiss_mih_ms) {
        std::printf(
            "%9s faiss IndexBinaryMultiHash: %.2f ms (p95 %.2f; %.1fx mild_lcd's time), ~%.0f B/feature;"
            " IndexBinaryFlat: %s ms\n",
            "", *faiss_mih_ms, faiss_mih.p95(), *faiss_mih_ms / mih_et.median(), faiss_bytes_per_feature,
            cell(faiss_exact_ms, "%.1f").c_str());
      }
      if (recall_unbounded) {
        std::printf(
            "%9s pairs within d0 found, of the exact search's (%zu queries): default %s, unbounded %s, faiss "
            "MultiHash %s\n",
            "", exact_pairs.size(), cell(shipped_measured ? recall_default : std::nullopt, "%.3f").c_str(),
            cell(recall_unbounded, "%.3f").c_str(), cell(recall_faiss, "%.3f").c_str());
      }
      if (!inlined.samples.empty()) {
        std::printf("%9s inline prefixes: %.2f ms (p95 %.2f), %.0f B/feature, insert %.2f ms\n", "", inlined.median(),
                    inlined.p95(), inline_bytes_per_feature, inline_insert_ms);
      }
      std::printf(
          "%9s insert: %.2f ms mean, %.2f ms over the last tenth, %.1f ms the slowest (p99 %.2f, %zu over 2 ms)\n", "",
          insert.mean_ms, insert.last_tenth_ms, insert.max_ms, insert.p99_ms, insert.over_2ms);
      if (!bounded.samples.empty()) {
        std::printf(
            "%9s bounded buckets (%u entries, query budget %u%s): %.2f ms (p95 %.2f), %.0f candidates per query "
            "feature, %.1f B/feature, insert %.2f ms over the last tenth, %.1f ms the slowest (p99 %.2f, %zu over 2 "
            "ms)\n",
            "", opt.bounded, opt.max_candidates, shipped_measured ? ", the shipped configuration" : "",
            bounded.median(), bounded.p95(),
            static_cast<double>(bounded_work.candidates_visited) / bounded_work.query_features,
            bounded_bytes_per_feature, bounded_insert.last_tenth_ms, bounded_insert.max_ms, bounded_insert.p99_ms,
            bounded_insert.over_2ms);
      }
      std::printf("%9s per query feature: %.0f candidates, %.0f full distances, %.1f votes\n", "",
                  row["candidates_per_query_feature"].get<double>(),
                  row["full_distances_per_query_feature"].get<double>(), row["votes_per_query_feature"].get<double>());
      std::fflush(stdout);
    }
  }
  // Growth: t(10k) / t(1k) when both were measured.
  json out = {{"faiss", MILD_HAVE_FAISS != 0},
              {"rows", rows},
              {"features_per_keyframe", opt.features},
              {"queries", queries.size()},
              {"keyframes_from", walk ? "sequence" : "replicated frames"}};
  if (opt.persistence_keyframes > 0 && (!walk || opt.persistence_keyframes <= walk->size())) {
    out["persistence"] = measurePersistence(keyframe_at, opt.persistence_keyframes);
    if (!opt.json) {
      const json& p = out["persistence"];
      std::printf("database file, %zu keyframes, %zu features: %.0f MB, save %.2f s, load %.2f s (index rebuilt)\n",
                  opt.persistence_keyframes, p["features"].get<size_t>(), p["file_mb"].get<double>(),
                  p["save_s"].get<double>(), p["load_s"].get<double>());
    }
  }
  double t1k = 0, t10k = 0;
  for (const auto& r : rows) {
    if (!r.contains("mih_et_ms_median")) continue;
    if (r["keyframes"] == 1000) t1k = r["mih_et_ms_median"];
    if (r["keyframes"] == 10000) t10k = r["mih_et_ms_median"];
  }
  if (t1k > 0 && t10k > 0) {
    out["growth_10k_over_1k"] = t10k / t1k;
    if (!opt.json) std::printf("t(10k) / t(1k) = %.2f\n", t10k / t1k);
  }
  if (opt.json) std::cout << out.dump() << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Query cost of the keyframe database at scale, against the 2017 MILD design and brute force."};
  app.name("mild_bench_scale");
  Options opt;
  app.add_option("--sizes", opt.sizes, "keyframe counts, comma-separated")->capture_default_str();
  app.add_option("--images", opt.images,
                 "sequences of real frames to replicate (default: ../shared/bench, else the sample)");
  app.add_option("--sequence", opt.sequence,
                 "build the databases from this walk's own frames in order (gen.py scale --frames N), not replicas")
      ->check(CLI::ExistingDirectory);
  app.add_option("--feature-type", opt.feature_type, "extractor: orb (256 bits), brisk (512), akaze (486)")
      ->capture_default_str();
  app.add_option("--features", opt.features, "features per keyframe")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--queries", opt.queries, "queries per size")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--brute-queries", opt.brute_queries, "brute-force queries per size")->capture_default_str();
  app.add_option("--brute-max-keyframes", opt.brute_max_keyframes, "largest size brute force runs at")
      ->capture_default_str();
  app.add_flag("--skip-baseline", opt.skip_baseline, "do not build the 2017 design");
  app.add_option("--faiss-max-keyframes", opt.faiss_max_keyframes, "largest size the faiss baselines run at (0: skip)")
      ->capture_default_str();
  app.add_option("--faiss-exact-queries", opt.faiss_exact_queries, "IndexBinaryFlat queries per size")
      ->capture_default_str();
  app.add_option("--inline-prefixes", opt.inline_prefixes,
                 "also time index/inline_prefixes (each entry's first 64 bits in its bucket)")
      ->capture_default_str();
  app.add_option("--bounded", opt.bounded,
                 "also time index/max_bucket_entries at this bound (0: skip; default: the shipped bound, i.e. the "
                 "shipped configuration)")
      ->capture_default_str();
  app.add_option("--max-candidates", opt.max_candidates,
                 "index/max_candidates_per_feature of the bounded (shipped) configuration (0: no query budget)")
      ->capture_default_str();
  app.add_option("--persistence-keyframes", opt.persistence_keyframes,
                 "time saving and loading a database of this many keyframes (0: skip)")
      ->capture_default_str();
  app.add_flag("--json", opt.json, "print one JSON object as the last line");
  return mild::tools::toolMain(app, argc, argv, [&] { return run(opt); });
}
