#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace mild {

// Scoring of loop-closure candidates against a bench sequence's gt_loops.txt, following
// ../shared/bench/EVALUATION.md exactly (the referee score.py must agree to 4 decimals):
//  - gt lines "i j overlap is_true": is_true = 1 pairs are right, is_true = 0 pairs are don't care,
//    any other pair is wrong; a loop query is a frame with at least one right pair;
//  - only each query's best-scoring candidate counts (the first one seen wins a tie), pairs with
//    i - j < min_gap are ignored;
//  - best candidates are ranked by score, equal scores entering together; recall@100%P is the
//    recall at the last step with no wrong candidate, AP sums precision x recall increments.

struct GroundTruth {
  std::set<std::pair<int, int>> right;
  std::set<std::pair<int, int>> dont_care;
  std::set<int> loop_queries;
};

struct ScoredPair {
  int query = 0;
  int candidate = 0;
  double score = 0.0;
};

struct PrPoint {
  double score = 0.0;
  double precision = 0.0;
  double recall = 0.0;
};

struct Metrics {
  size_t loop_queries = 0;
  size_t scored_queries = 0;
  size_t true_positives = 0;
  size_t false_positives = 0;
  double recall_at_100_precision = 0.0;
  double average_precision = 0.0;
  double max_f1 = 0.0;
  std::vector<PrPoint> curve;
};

// Throws InvalidInput naming the file and line for unreadable files, malformed lines, pairs that are
// not 0 <= j < i (< frames when frames >= 0, the sequence's length) and files without any pair.
// Blank lines and lines starting with '#' are skipped.
GroundTruth loadGroundTruth(const std::string& path, long frames = -1);

// Reads a candidates CSV (rows "query,candidate,score", header optional) the way score.py does.
// Throws InvalidInput naming the file when it cannot be opened.
std::vector<ScoredPair> loadCandidates(const std::string& path);

// Each query's best candidate (first seen wins a tie), pairs closer than min_gap dropped; by query.
std::vector<ScoredPair> bestPerQuery(const std::vector<ScoredPair>& candidates, int min_gap = 40);

Metrics evaluate(const GroundTruth& truth, const std::vector<ScoredPair>& candidates, int min_gap = 40);

// The hard decision "act on candidates scoring at least `threshold`", over each query's best
// candidate: right and wrong ones (don't-care skipped), precision, and recall over the loop queries.
struct Decision {
  double threshold = 0.5;
  size_t right = 0;
  size_t wrong = 0;
  double precision = 1.0;  // 1 when nothing is accepted
  double recall = 0.0;
};
Decision decideAt(const GroundTruth& truth, const std::vector<ScoredPair>& candidates, double threshold,
                  int min_gap = 40);

// Reliability of the scores as probabilities, over each query's best candidate (don't-care
// skipped): `bins` equal-width bins of the score in [0, 1], each with its count, mean score and
// fraction right; the expected calibration error is the count-weighted mean |fraction - mean score|.
struct ReliabilityBin {
  double lower = 0.0, upper = 0.0;
  size_t count = 0;
  double mean_score = 0.0;
  double fraction_right = 0.0;
};
struct Reliability {
  std::vector<ReliabilityBin> bins;
  double expected_calibration_error = 0.0;
  size_t scored = 0;
};
Reliability reliability(const GroundTruth& truth, const std::vector<ScoredPair>& candidates, int bins = 10,
                        int min_gap = 40);

// Scores as written to CSV: enough digits that ranking and ties survive the round trip.
std::string formatScore(double score);

}  // namespace mild
