#include "mild_lcd/offline/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "mild_lcd/common/errors.hpp"

namespace mild {

GroundTruth loadGroundTruth(const std::string& path, long frames) {
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) {
    throw InvalidInput(path + ": not a ground-truth file (missing, or not a regular file)");
  }
  std::ifstream in(path);
  if (!in) throw InvalidInput(path + ": cannot open the ground-truth file");
  GroundTruth gt;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    std::istringstream fields(line);
    std::string first;
    if (!(fields >> first) || first[0] == '#') continue;
    std::istringstream row(line);
    long i = 0, j = 0;
    double overlap = 0.0;
    std::string is_true;
    if (!(row >> i >> j >> overlap >> is_true) || (is_true != "0" && is_true != "1")) {
      throw InvalidInput(path + ":" + std::to_string(number) +
                         ": expected 'i j overlap is_true' (is_true 0 or 1), got '" + line + "'");
    }
    if (j < 0 || i <= j || i > INT32_MAX || (frames >= 0 && i >= frames)) {
      throw InvalidInput(path + ":" + std::to_string(number) + ": frame pair " + std::to_string(i) + " " +
                         std::to_string(j) +
                         (frames >= 0 ? " is not 0 <= j < i < " + std::to_string(frames) + " (the sequence's frames)"
                                      : " is not 0 <= j < i"));
    }
    const std::pair<int, int> pair(static_cast<int>(i), static_cast<int>(j));
    if (is_true == "1") {
      gt.right.insert(pair);
      gt.loop_queries.insert(pair.first);
    } else {
      gt.dont_care.insert(pair);
    }
  }
  if (in.bad()) throw InvalidInput(path + ": read error");
  if (gt.right.empty() && gt.dont_care.empty())
    throw InvalidInput(path + ": holds no frame pairs (empty ground truth)");
  return gt;
}

std::vector<ScoredPair> loadCandidates(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InvalidInput(path + ": cannot open the candidates file");
  std::vector<ScoredPair> out;
  std::string line;
  size_t line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream row(line);
    std::string a, b, c;
    if (!(row >> a >> b >> c)) continue;
    try {
      size_t ua = 0, ub = 0, uc = 0;
      ScoredPair p{std::stoi(a, &ua), std::stoi(b, &ub), std::stod(c, &uc)};
      if (ua == a.size() && ub == b.size() && uc == c.size()) {
        // A score that is not a number cannot be ranked: refused, not guessed at.
        if (!std::isfinite(p.score)) {
          throw InvalidInput(path + ":" + std::to_string(line_number) + ": the score '" + c +
                             "' is not a finite number");
        }
        out.push_back(p);
      }
    } catch (const std::logic_error&) {
      // a header row, as score.py skips it (std::stoi / std::stod throw invalid_argument or out_of_range)
    }
  }
  return out;
}

std::vector<ScoredPair> bestPerQuery(const std::vector<ScoredPair>& candidates, int min_gap) {
  std::map<int, ScoredPair> best;
  for (const ScoredPair& c : candidates) {
    if (static_cast<int64_t>(c.query) - static_cast<int64_t>(c.candidate) < min_gap) continue;
    auto it = best.find(c.query);
    if (it == best.end() || c.score > it->second.score) best[c.query] = c;
  }
  std::vector<ScoredPair> out;
  for (const auto& kv : best) out.push_back(kv.second);
  return out;
}

Metrics evaluate(const GroundTruth& truth, const std::vector<ScoredPair>& candidates, int min_gap) {
  std::vector<ScoredPair> ranked = bestPerQuery(candidates, min_gap);
  std::stable_sort(ranked.begin(), ranked.end(),
                   [](const ScoredPair& a, const ScoredPair& b) { return a.score > b.score; });

  Metrics m;
  m.loop_queries = truth.loop_queries.size();
  m.scored_queries = ranked.size();
  std::set<int> hit;
  const double loop_queries = static_cast<double>(std::max<size_t>(1, m.loop_queries));
  for (size_t k = 0; k < ranked.size();) {
    const double score = ranked[k].score;
    // Each step takes at least one pair, so that the walk ends whatever the scores compare like.
    for (size_t first = k; k < ranked.size() && (k == first || ranked[k].score == score); ++k) {
      const std::pair<int, int> pair(ranked[k].query, ranked[k].candidate);
      if (truth.right.count(pair)) {
        ++m.true_positives;
        hit.insert(pair.first);
      } else if (!truth.dont_care.count(pair)) {
        ++m.false_positives;
      }
    }
    PrPoint p;
    p.score = score;
    p.recall = static_cast<double>(hit.size()) / loop_queries;
    p.precision = static_cast<double>(m.true_positives) /
                  static_cast<double>(std::max<size_t>(1, m.true_positives + m.false_positives));
    m.curve.push_back(p);
    if (m.false_positives == 0) m.recall_at_100_precision = p.recall;
  }
  double previous_recall = 0.0;
  for (const PrPoint& p : m.curve) {
    m.average_precision += p.precision * (p.recall - previous_recall);
    previous_recall = p.recall;
    if (p.precision + p.recall > 0.0)
      m.max_f1 = std::max(m.max_f1, 2 * p.precision * p.recall / (p.precision + p.recall));
  }
  return m;
}

std::string formatScore(double score) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.10g", score);
  return buffer;
}

Decision decideAt(const GroundTruth& truth, const std::vector<ScoredPair>& candidates, double threshold, int min_gap) {
  Decision d;
  d.threshold = threshold;
  for (const ScoredPair& c : bestPerQuery(candidates, min_gap)) {
    if (c.score < threshold) continue;
    const std::pair<int, int> pair(c.query, c.candidate);
    if (truth.right.count(pair)) {
      ++d.right;
    } else if (!truth.dont_care.count(pair)) {
      ++d.wrong;
    }
  }
  if (d.right + d.wrong > 0) d.precision = static_cast<double>(d.right) / static_cast<double>(d.right + d.wrong);
  d.recall =
      truth.loop_queries.empty() ? 0.0 : static_cast<double>(d.right) / static_cast<double>(truth.loop_queries.size());
  return d;
}

Reliability reliability(const GroundTruth& truth, const std::vector<ScoredPair>& candidates, int bins, int min_gap) {
  Reliability r;
  r.bins.resize(static_cast<size_t>(std::max(1, bins)));
  for (size_t b = 0; b < r.bins.size(); ++b) {
    r.bins[b].lower = static_cast<double>(b) / static_cast<double>(r.bins.size());
    r.bins[b].upper = static_cast<double>(b + 1) / static_cast<double>(r.bins.size());
  }
  std::vector<double> right(r.bins.size(), 0.0);
  for (const ScoredPair& c : bestPerQuery(candidates, min_gap)) {
    const std::pair<int, int> pair(c.query, c.candidate);
    const bool is_right = truth.right.count(pair) > 0;
    if (!is_right && truth.dont_care.count(pair)) continue;
    const double score = std::clamp(c.score, 0.0, 1.0);
    const size_t b = std::min(r.bins.size() - 1, static_cast<size_t>(score * static_cast<double>(r.bins.size())));
    ++r.bins[b].count;
    r.bins[b].mean_score += score;
    right[b] += is_right ? 1.0 : 0.0;
    ++r.scored;
  }
  for (size_t b = 0; b < r.bins.size(); ++b) {
    ReliabilityBin& bin = r.bins[b];
    if (bin.count == 0) continue;
    bin.mean_score /= static_cast<double>(bin.count);
    bin.fraction_right = right[b] / static_cast<double>(bin.count);
    r.expected_calibration_error += static_cast<double>(bin.count) * std::abs(bin.fraction_right - bin.mean_score);
  }
  if (r.scored > 0) r.expected_calibration_error /= static_cast<double>(r.scored);
  return r;
}

}  // namespace mild
