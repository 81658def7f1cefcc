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
#include "mild_lcd/detector/loop_detector.hpp"
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
  mild::MapState state;
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
  detector.map().restore(std::move(state), false);
  const fs::path file = fs::temp_directory_path() / ("mild_bench_scale_" + std::to_string(::getpid()) + ".mild");
  auto t = Clock::now();
  mild::saveMap(detector.map(), file.string());
  const double save_s = msSince(t) / 1000.0;
  mild::LoopDetector loaded(params);
  t = Clock::now();
  const mild::LoadReport report = mild::loadMap(loaded.map(), file.string(), true);
  const double load_s = msSince(t) / 1000.0;
  const double file_mb = static_cast<double>(fs::file_size(file)) / 1e6;
  fs::remove(file);
  return {
      {"keyframes", n}, {"features", report.features}, {"file_mb", file_mb}, {"save_s", save_s}, {"load_s", load_s}};
}

// What every size is measured on: the stored keyframes (a prefix of keyframe_at), the queries and
// the sizes.
struct Workload {
  std::optional<mild::tools::SequenceKeyframes> walk;
  std::optional<mild::tools::SyntheticKeyframes> synthetic;
  std::vector<mild::DescriptorList> queries;
  KeyframeAt keyframe_at;
  std::vector<size_t> sizes;
};

// Keyframes: a real walk's frames (--sequence), or real frames replicated to any size. Filled in
// place: keyframe_at reads the workload's own keyframes.
void loadWorkload(const Options& opt, const std::vector<std::string>& dirs, const mild::FeatureExtractor& extractor,
                  Workload& w) {
  w.sizes = parseSizes(opt.sizes);
  if (!opt.sequence.empty()) {
    w.walk.emplace(opt.sequence, extractor, opt.queries);
    w.queries = w.walk->queries();
    w.keyframe_at = [&w](size_t k) { return w.walk->keyframe(k); };
    // Prefixes of the walk, and the whole walk.
    const size_t total = w.walk->size();
    w.sizes.erase(std::remove_if(w.sizes.begin(), w.sizes.end(), [&](size_t n) { return n >= total; }), w.sizes.end());
    w.sizes.push_back(total);
    if (!opt.json) {
      std::printf("walk %s: %zu stored keyframes, %zu held-out queries; up to %d features per keyframe; one thread\n",
                  opt.sequence.c_str(), total, w.queries.size(), opt.features);
    }
    return;
  }
  std::vector<mild::DescriptorList> real;
  for (const auto& dir : dirs) {
    for (const auto& path : mild::tools::openImageSequence(dir).frames) {
      const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
      if (!image.empty()) real.push_back(extractor.extract(image, mild::PixelFormat::kGray).descriptors);
    }
  }
  w.synthetic.emplace(std::move(real), static_cast<size_t>(opt.features));
  for (int q = 0; q < opt.queries; ++q) w.queries.push_back(w.synthetic->query(q));
  w.keyframe_at = [&w](size_t k) { return w.synthetic->keyframe(k); };
  if (!opt.json) {
    std::printf("%zu real frames from %zu sequence(s); %d features per keyframe; %d queries per size; one thread\n",
                w.synthetic->realFrames(), dirs.size(), opt.features, opt.queries);
  }
}

// One mild_lcd index built from the first n keyframes and asked every query.
struct IndexRun {
  Timing timing;
  mild::QueryStats work;
  InsertTiming insert;
  double bytes_per_feature = 0.0;
  std::vector<uint64_t> pairs;  // per query: pairs (query feature, stored feature) within d0, what votes
};

// Inserts the first n keyframes into `db` and asks it every query.
IndexRun insertAndQuery(mild::KeyframeDatabase& db, const Workload& w, size_t n) {
  IndexRun run;
  run.insert = insertAll(db, w.keyframe_at, n);
  run.bytes_per_feature = static_cast<double>(db.memoryBytes()) / static_cast<double>(db.featureCount());
  for (const auto& q : w.queries) {
    auto t = Clock::now();
    const auto r = db.query(q);
    run.timing.samples.push_back(msSince(t));
    run.work += r.stats;
    run.pairs.push_back(r.stats.votes);
  }
  return run;
}

IndexRun measureIndex(const Workload& w, size_t n, const mild::DatabaseParams& params) {
  mild::KeyframeDatabase db(params);
  return insertAndQuery(db, w, n);
}

// The same index with each entry's first 64 bits beside its id.
mild::DatabaseParams inlinePrefixes(mild::DatabaseParams params) {
  params.index.inline_prefixes = true;
  return params;
}

// The same, with max_bucket_entries: query time bounded as the map grows.
mild::DatabaseParams boundedBuckets(mild::DatabaseParams params, uint32_t bound, uint32_t max_candidates) {
  params.index.max_bucket_entries = bound;
  params.index.max_candidates_per_feature = max_candidates;
  return params;
}

// The MIH columns: the index unbounded, queried with early termination (mih_et), then the same
// index without it (the threshold at 64: mih), then its exact brute force on small maps.
struct MihRun {
  Timing mih, mih_et, brute;
  mild::QueryStats work;
  InsertTiming insert;
  double bytes_per_feature = 0.0;
  std::vector<uint64_t> pairs;
};

MihRun measureMih(const Options& opt, const Workload& w, size_t n, const mild::DatabaseParams& et_params,
                  const mild::DatabaseParams& full_params) {
  MihRun run;
  mild::KeyframeDatabase db(et_params);
  IndexRun with_et = insertAndQuery(db, w, n);
  run.mih_et = std::move(with_et.timing);
  run.work = with_et.work;
  run.insert = with_et.insert;
  run.bytes_per_feature = with_et.bytes_per_feature;
  run.pairs = std::move(with_et.pairs);
  db.setSimilarityParams(full_params.similarity);
  for (const auto& q : w.queries) {
    auto t = Clock::now();
    const auto r = db.query(q);
    run.mih.samples.push_back(msSince(t));
    (void)r;
  }
  if (n <= opt.brute_max_keyframes) {
    for (int q = 0; q < std::min<int>(opt.brute_queries, static_cast<int>(w.queries.size())); ++q) {
      auto t = Clock::now();
      const auto r = db.query(w.queries[q], mild::kAllKeyframes, mild::SearchMode::kExact);
      run.brute.samples.push_back(msSince(t));
      (void)r;
    }
  }
  return run;
}

// faiss on the same descriptors, range search within d0: IndexBinaryMultiHash for every query,
// IndexBinaryFlat (exact) for the first faiss_exact_queries, whose pairs are the truth the others'
// recall is measured against.
struct FaissRun {
  Timing mih, exact;
  double bytes_per_feature = 0.0;
  size_t mih_pairs_first = 0, exact_pairs_first = 0;  // of the first query, a check on both
  std::vector<uint64_t> pairs, exact_pairs;
};

FaissRun measureFaiss(const Options& opt, const Workload& w, size_t n, const mild::DatabaseParams& et_params) {
  FaissRun run;
#if MILD_HAVE_FAISS
  const int bits = et_params.descriptor_bytes * 8;
  mild::tools::FaissBaselines faiss(bits, et_params.index.tablesFor(bits));
  for (size_t k = 0; k < n; ++k) faiss.add(w.keyframe_at(k));
  run.bytes_per_feature = faiss.entryBytesPerFeature();
  const int d0 = et_params.similarity.scaledTo(bits).max_distance;
  for (const auto& q : w.queries) {
    auto t = Clock::now();
    const size_t found = faiss.queryMultiHash(q, d0);
    run.mih.samples.push_back(msSince(t));
    if (&q == &w.queries.front()) run.mih_pairs_first = found;
    run.pairs.push_back(found);
  }
  for (int q = 0; q < std::min<int>(opt.faiss_exact_queries, static_cast<int>(w.queries.size())); ++q) {
    auto t = Clock::now();
    const size_t found = faiss.queryExact(w.queries[q], d0);
    run.exact.samples.push_back(msSince(t));
    if (q == 0) run.exact_pairs_first = found;
    run.exact_pairs.push_back(found);
  }
#else
  (void)opt, (void)w, (void)n, (void)et_params;  // built without faiss: no columns (main() says so)
#endif
  return run;
}

// Our reproduction of the 2017 index design.
Timing measure2017(const Workload& w, size_t n, const mild::DatabaseParams& et_params) {
  Timing timing;
  mild::tools::Mild2017Index old(et_params);
  for (size_t k = 0; k < n; ++k) old.insert(w.keyframe_at(k));
  for (const auto& q : w.queries) {
    auto t = Clock::now();
    const auto r = old.query(q);
    timing.samples.push_back(msSince(t));
    (void)r;
  }
  return timing;
}

std::unique_ptr<mild::FeatureExtractor> makeExtractor(const Options& opt) {
  mild::FeatureParams feature_params;
  feature_params.type = opt.feature_type;
  // Every extractor's budget, whichever the type names.
  mild::forEachSection(feature_params.extractors, [&](auto& section) { section.num_features = opt.features; });
  return mild::makeFeatureExtractor(feature_params);
}

// The MIH columns are the index without the bound on bucket length or the query budget (early
// termination at 20 of the first 64 bits as shipped); the bounded column adds both, and with the
// shipped values it is the shipped configuration (config/default.yaml).
mild::DatabaseParams unboundedParams(const mild::FeatureExtractor& extractor) {
  mild::DatabaseParams et_params;
  et_params.descriptor_bytes = extractor.descriptorBytes();
  et_params.index.max_bucket_entries = 0;  // the index unbounded: every bucket whole, every entry read
  et_params.index.max_candidates_per_feature = 0;
  return et_params;
}

// The same index without early termination.
mild::DatabaseParams withoutEarlyTermination(mild::DatabaseParams params) {
  params.similarity.early_termination_threshold = 64;  // never rejects early
  return params;
}

// mild_lcd needs ~100 bytes per feature (~230 with inline prefixes), the 2017 design ~170; one after the other.
size_t bytesNeeded(const Options& opt, const Workload& w, size_t n) {
  size_t features = n * static_cast<size_t>(opt.features);
  if (w.walk) {
    features = 0;
    for (size_t k = 0; k < n; ++k) features += w.walk->keyframe(k).size();
  }
  return features * (opt.inline_prefixes ? 260 : 200);
}

void printTableHeader() {
  std::printf("%9s %11s %11s %12s %12s %12s %10s %9s %9s %9s\n", "keyframes", "mih_ms", "mih_et_ms", "mih_et_p95",
              "mild2017_ms", "brute_ms", "B/feature", "insert_ms", "x2017", "xbrute");
}

// Everything measured at one size.
struct SizeRuns {
  MihRun unbounded;
  IndexRun inlined;
  IndexRun bounded;
  FaissRun faiss;
  Timing baseline;
};

// Each baseline in turn, in this order (the machine's state moves with the run).
SizeRuns measureSize(const Options& opt, const Workload& w, size_t n, const mild::DatabaseParams& et_params,
                     const mild::DatabaseParams& full_params) {
  SizeRuns runs;
  runs.unbounded = measureMih(opt, w, n, et_params, full_params);
  runs.inlined = opt.inline_prefixes ? measureIndex(w, n, inlinePrefixes(et_params)) : IndexRun{};
  runs.bounded =
      opt.bounded > 0 ? measureIndex(w, n, boundedBuckets(et_params, opt.bounded, opt.max_candidates)) : IndexRun{};
  runs.faiss = n <= opt.faiss_max_keyframes ? measureFaiss(opt, w, n, et_params) : FaissRun{};
  // The 2017 design is ORB's 16 tables of 16 bits.
  const int bits = et_params.descriptor_bytes * 8;
  runs.baseline = !opt.skip_baseline && bits == 256 ? measure2017(w, n, et_params) : Timing{};
  return runs;
}

// The shipped configuration's figures: the bounded database when its bound is the shipped one.
struct Shipped {
  bool measured;
  const Timing& timing;
  const mild::QueryStats& work;
  const InsertTiming& insert;
  double bytes_per_feature;
  const std::vector<uint64_t>& pairs;
};

Shipped shippedConfiguration(const Options& opt, const SizeRuns& runs) {
  const uint32_t shipped_bound = mild::MihParams{}.max_bucket_entries;
  const MihRun& unbounded = runs.unbounded;
  const IndexRun& bounded = runs.bounded;
  const bool measured = opt.max_candidates == mild::MihParams{}.max_candidates_per_feature &&
                        (shipped_bound == 0 || (opt.bounded == shipped_bound && !bounded.timing.samples.empty()));
  if (shipped_bound == 0) {
    return {measured, unbounded.mih_et, unbounded.work, unbounded.insert, unbounded.bytes_per_feature, unbounded.pairs};
  }
  return {measured, bounded.timing, bounded.work, bounded.insert, bounded.bytes_per_feature, bounded.pairs};
}

// Share of the exact search's pairs within d0 that `found` has, over the queries the exact search
// answered; nullopt without exact pairs to compare with.
std::optional<double> pairRecall(const std::vector<uint64_t>& exact_pairs, const std::vector<uint64_t>& found) {
  const size_t n_queries = exact_pairs.size();
  if (n_queries == 0 || found.size() < n_queries) return std::nullopt;
  const double truth = std::accumulate(exact_pairs.begin(), exact_pairs.end(), 0.0);
  return truth > 0 ? std::optional<double>(std::accumulate(found.begin(), found.begin() + n_queries, 0.0) / truth)
                   : std::nullopt;
}

// The figures a size may lack: nullopt where the baseline did not run.
struct OptionalFigures {
  std::optional<double> brute_ms, base_ms, faiss_mih_ms, faiss_exact_ms;
  std::optional<double> recall_default, recall_unbounded, recall_faiss;
};

OptionalFigures optionalFigures(const SizeRuns& runs, const Shipped& shipped) {
  const Timing& brute = runs.unbounded.brute;
  const Timing& baseline = runs.baseline;
  const Timing& faiss_mih = runs.faiss.mih;
  const Timing& faiss_exact = runs.faiss.exact;
  const std::vector<uint64_t>& exact_pairs = runs.faiss.exact_pairs;
  OptionalFigures f;
  f.brute_ms = brute.samples.empty() ? std::nullopt : std::optional<double>(brute.median());
  f.base_ms = baseline.samples.empty() ? std::nullopt : std::optional<double>(baseline.median());
  f.faiss_mih_ms = faiss_mih.samples.empty() ? std::nullopt : std::optional<double>(faiss_mih.median());
  f.faiss_exact_ms = faiss_exact.samples.empty() ? std::nullopt : std::optional<double>(faiss_exact.median());
  f.recall_default = pairRecall(exact_pairs, shipped.pairs);
  f.recall_unbounded = pairRecall(exact_pairs, runs.unbounded.pairs);
  f.recall_faiss = pairRecall(exact_pairs, runs.faiss.pairs);
  return f;
}

json sizeRow(const Options& opt, size_t n, const SizeRuns& runs, const Shipped& shipped, const OptionalFigures& f) {
  const Timing& mih = runs.unbounded.mih;
  const Timing& mih_et = runs.unbounded.mih_et;
  const mild::QueryStats& work = runs.unbounded.work;
  const InsertTiming& insert = runs.unbounded.insert;
  const Timing& inlined = runs.inlined.timing;
  const Timing& bounded = runs.bounded.timing;
  const FaissRun& faiss = runs.faiss;
  json row = {{"keyframes", n}};
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
  row["default_ms_median"] = shipped.measured ? json(shipped.timing.median()) : json(nullptr);
  row["default_ms_p95"] = shipped.measured ? json(shipped.timing.p95()) : json(nullptr);
  row["default_bytes_per_feature"] = shipped.measured ? json(shipped.bytes_per_feature) : json(nullptr);
  row["default_insert_ms_last_tenth"] = shipped.measured ? json(shipped.insert.last_tenth_ms) : json(nullptr);
  row["default_insert_ms_max"] = shipped.measured ? json(shipped.insert.max_ms) : json(nullptr);
  row["default_insert_ms_p99"] = shipped.measured ? json(shipped.insert.p99_ms) : json(nullptr);
  row["default_inserts_over_2ms"] = shipped.measured ? json(shipped.insert.over_2ms) : json(nullptr);
  row["default_candidates_per_query_feature"] =
      shipped.measured ? json(static_cast<double>(shipped.work.candidates_visited) / shipped.work.query_features)
                       : json(nullptr);
  row["mih_inline_ms_median"] = inlined.samples.empty() ? json(nullptr) : json(inlined.median());
  row["mih_inline_ms_p95"] = inlined.samples.empty() ? json(nullptr) : json(inlined.p95());
  row["inline_bytes_per_feature"] = inlined.samples.empty() ? json(nullptr) : json(runs.inlined.bytes_per_feature);
  row["inline_insert_ms"] = inlined.samples.empty() ? json(nullptr) : json(runs.inlined.insert.mean_ms);
  row["baseline_2017_ms_median"] = nullable(f.base_ms);
  row["baseline_2017_ms_p95"] = f.base_ms ? json(runs.baseline.p95()) : json(nullptr);
  row["brute_ms_median"] = nullable(f.brute_ms);
  row["faiss_mih_ms_median"] = nullable(f.faiss_mih_ms);
  row["faiss_multihash_ms_median"] = nullable(f.faiss_mih_ms);  // the name issue 16 asks for
  row["faiss_mih_ms_p95"] = f.faiss_mih_ms ? json(faiss.mih.p95()) : json(nullptr);
  row["faiss_exact_ms_median"] = nullable(f.faiss_exact_ms);
  row["faiss_mih_pairs_first_query"] = f.faiss_mih_ms ? json(faiss.mih_pairs_first) : json(nullptr);
  row["faiss_exact_pairs_first_query"] = f.faiss_exact_ms ? json(faiss.exact_pairs_first) : json(nullptr);
  row["faiss_mih_bytes_per_feature"] = f.faiss_mih_ms ? json(faiss.bytes_per_feature) : json(nullptr);
  row["speedup_vs_faiss_mih"] = f.faiss_mih_ms ? json(*f.faiss_mih_ms / mih_et.median()) : json(nullptr);
  row["speedup_vs_faiss_exact"] = f.faiss_exact_ms ? json(*f.faiss_exact_ms / mih_et.median()) : json(nullptr);
  row["pair_recall_queries"] = faiss.exact_pairs.size();
  row["pair_recall_default"] = shipped.measured ? nullable(f.recall_default) : json(nullptr);
  row["pair_recall_unbounded"] = nullable(f.recall_unbounded);
  row["pair_recall_faiss_multihash"] = nullable(f.recall_faiss);
  row["bytes_per_feature"] = runs.unbounded.bytes_per_feature;
  row["candidates_per_query_feature"] = static_cast<double>(work.candidates_visited) / work.query_features;
  row["full_distances_per_query_feature"] = static_cast<double>(work.full_distances) / work.query_features;
  row["votes_per_query_feature"] = static_cast<double>(work.votes) / work.query_features;
  row["insert_ms_per_keyframe"] = insert.mean_ms;
  row["insert_ms_last_tenth"] = insert.last_tenth_ms;
  row["insert_ms_max"] = insert.max_ms;
  row["insert_ms_p99"] = insert.p99_ms;
  row["inserts_over_2ms"] = insert.over_2ms;
  row["speedup_vs_2017"] = f.base_ms ? json(*f.base_ms / mih_et.median()) : json(nullptr);
  row["speedup_vs_brute"] = f.brute_ms ? json(*f.brute_ms / mih_et.median()) : json(nullptr);
  return row;
}

std::string cell(std::optional<double> v, const char* fmt) {
  char buf[32];
  if (!v) return std::string("-");
  std::snprintf(buf, sizeof(buf), fmt, *v);
  return std::string(buf);
}

void printSizeRow(const Options& opt, size_t n, const SizeRuns& runs, const Shipped& shipped, const OptionalFigures& f,
                  const json& row) {
  const Timing& mih_et = runs.unbounded.mih_et;
  const InsertTiming& insert = runs.unbounded.insert;
  const IndexRun& inline_run = runs.inlined;
  const IndexRun& bounded_run = runs.bounded;
  std::printf("%9zu %11.2f %11.2f %12.2f %12s %12s %10.1f %9.2f %9s %9s\n", n, runs.unbounded.mih.median(),
              mih_et.median(), mih_et.p95(), cell(f.base_ms, "%.2f").c_str(), cell(f.brute_ms, "%.1f").c_str(),
              runs.unbounded.bytes_per_feature, insert.mean_ms,
              cell(f.base_ms ? std::optional<double>(*f.base_ms / mih_et.median()) : std::nullopt, "%.1fx").c_str(),
              cell(f.brute_ms ? std::optional<double>(*f.brute_ms / mih_et.median()) : std::nullopt, "%.0fx").c_str());
  if (f.faiss_mih_ms) {
    std::printf(
        "%9s faiss IndexBinaryMultiHash: %.2f ms (p95 %.2f; %.1fx mild_lcd's time), ~%.0f B/feature;"
        " IndexBinaryFlat: %s ms\n",
        "", *f.faiss_mih_ms, runs.faiss.mih.p95(), *f.faiss_mih_ms / mih_et.median(), runs.faiss.bytes_per_feature,
        cell(f.faiss_exact_ms, "%.1f").c_str());
  }
  if (f.recall_unbounded) {
    std::printf(
        "%9s pairs within d0 found, of the exact search's (%zu queries): default %s, unbounded %s, faiss "
        "MultiHash %s\n",
        "", runs.faiss.exact_pairs.size(), cell(shipped.measured ? f.recall_default : std::nullopt, "%.3f").c_str(),
        cell(f.recall_unbounded, "%.3f").c_str(), cell(f.recall_faiss, "%.3f").c_str());
  }
  if (!inline_run.timing.samples.empty()) {
    std::printf("%9s inline prefixes: %.2f ms (p95 %.2f), %.0f B/feature, insert %.2f ms\n", "",
                inline_run.timing.median(), inline_run.timing.p95(), inline_run.bytes_per_feature,
                inline_run.insert.mean_ms);
  }
  std::printf("%9s insert: %.2f ms mean, %.2f ms over the last tenth, %.1f ms the slowest (p99 %.2f, %zu over 2 ms)\n",
              "", insert.mean_ms, insert.last_tenth_ms, insert.max_ms, insert.p99_ms, insert.over_2ms);
  if (!bounded_run.timing.samples.empty()) {
    std::printf(
        "%9s bounded buckets (%u entries, query budget %u%s): %.2f ms (p95 %.2f), %.0f candidates per query "
        "feature, %.1f B/feature, insert %.2f ms over the last tenth, %.1f ms the slowest (p99 %.2f, %zu over 2 "
        "ms)\n",
        "", opt.bounded, opt.max_candidates, shipped.measured ? ", the shipped configuration" : "",
        bounded_run.timing.median(), bounded_run.timing.p95(),
        static_cast<double>(bounded_run.work.candidates_visited) / bounded_run.work.query_features,
        bounded_run.bytes_per_feature, bounded_run.insert.last_tenth_ms, bounded_run.insert.max_ms,
        bounded_run.insert.p99_ms, bounded_run.insert.over_2ms);
  }
  std::printf("%9s per query feature: %.0f candidates, %.0f full distances, %.1f votes\n", "",
              row["candidates_per_query_feature"].get<double>(), row["full_distances_per_query_feature"].get<double>(),
              row["votes_per_query_feature"].get<double>());
  std::fflush(stdout);
}

// Growth: t(10k) / t(1k) when both were measured.
void addGrowth(const Options& opt, const json& rows, json& out) {
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
}

void addPersistence(const Options& opt, const Workload& w, json& out) {
  if (opt.persistence_keyframes > 0 && (!w.walk || opt.persistence_keyframes <= w.walk->size())) {
    out["persistence"] = measurePersistence(w.keyframe_at, opt.persistence_keyframes);
    if (!opt.json) {
      const json& p = out["persistence"];
      std::printf("database file, %zu keyframes, %zu features: %.0f MB, save %.2f s, load %.2f s (index rebuilt)\n",
                  opt.persistence_keyframes, p["features"].get<size_t>(), p["file_mb"].get<double>(),
                  p["save_s"].get<double>(), p["load_s"].get<double>());
    }
  }
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

  const std::unique_ptr<mild::FeatureExtractor> extractor_owner = makeExtractor(opt);
  const mild::FeatureExtractor& extractor = *extractor_owner;
  Workload workload;
  loadWorkload(opt, dirs, extractor, workload);

  const mild::DatabaseParams et_params = unboundedParams(extractor);
  const mild::DatabaseParams full_params = withoutEarlyTermination(et_params);

  json rows = json::array();
  if (!opt.json) printTableHeader();
  for (size_t n : workload.sizes) {
    const size_t bytes_needed = bytesNeeded(opt, workload, n);
    if (bytes_needed > availableMemoryBytes()) {
      if (!opt.json)
        std::printf("%9zu skipped: needs about %.1f GB, %.1f GB available\n", n, bytes_needed / 1e9,
                    availableMemoryBytes() / 1e9);
      rows.push_back({{"keyframes", n}, {"skipped", "memory"}});
      continue;
    }
    const SizeRuns runs = measureSize(opt, workload, n, et_params, full_params);
    const Shipped shipped = shippedConfiguration(opt, runs);
    const OptionalFigures figures = optionalFigures(runs, shipped);
    const json row = sizeRow(opt, n, runs, shipped, figures);
    rows.push_back(row);
    if (!opt.json) printSizeRow(opt, n, runs, shipped, figures, row);
  }
  json out = {{"faiss", MILD_HAVE_FAISS != 0},
              {"rows", rows},
              {"features_per_keyframe", opt.features},
              {"queries", workload.queries.size()},
              {"keyframes_from", workload.walk ? "sequence" : "replicated frames"}};
  addPersistence(opt, workload, out);
  addGrowth(opt, rows, out);
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
