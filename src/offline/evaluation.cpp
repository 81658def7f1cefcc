#include "mild_lcd/offline/evaluation.hpp"

#include <algorithm>
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
      throw InvalidInput(path + ":" + std::to_string(number) + ": expected 'i j overlap is_true' (is_true 0 or 1), got '" +
                         line + "'");
    }
    if (j < 0 || i <= j || i > INT32_MAX || (frames >= 0 && i >= frames)) {
      throw InvalidInput(path + ":" + std::to_string(number) + ": frame pair " + std::to_string(i) + " " + std::to_string(j) +
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
  if (gt.right.empty() && gt.dont_care.empty()) throw InvalidInput(path + ": holds no frame pairs (empty ground truth)");
  return gt;
}

std::vector<ScoredPair> loadCandidates(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InvalidInput(path + ": cannot open the candidates file");
  std::vector<ScoredPair> out;
  std::string line;
  while (std::getline(in, line)) {
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream row(line);
    std::string a, b, c;
    if (!(row >> a >> b >> c)) continue;
    try {
      size_t ua = 0, ub = 0, uc = 0;
      ScoredPair p{std::stoi(a, &ua), std::stoi(b, &ub), std::stod(c, &uc)};
      if (ua == a.size() && ub == b.size() && uc == c.size()) out.push_back(p);
    } catch (const std::exception&) {
      // a header row, as score.py skips it
    }
  }
  return out;
}

std::vector<ScoredPair> bestPerQuery(const std::vector<ScoredPair>& candidates, int min_gap) {
  std::map<int, ScoredPair> best;
  for (const ScoredPair& c : candidates) {
    if (c.query - c.candidate < min_gap) continue;
    auto it = best.find(c.query);
    if (it == best.end() || c.score > it->second.score) best[c.query] = c;
  }
  std::vector<ScoredPair> out;
  for (const auto& kv : best) out.push_back(kv.second);
  return out;
}

Metrics evaluate(const GroundTruth& truth, const std::vector<ScoredPair>& candidates, int min_gap) {
  std::vector<ScoredPair> ranked = bestPerQuery(candidates, min_gap);
  std::stable_sort(ranked.begin(), ranked.end(), [](const ScoredPair& a, const ScoredPair& b) { return a.score > b.score; });

  Metrics m;
  m.loop_queries = truth.loop_queries.size();
  m.scored_queries = ranked.size();
  std::set<int> hit;
  const double loop_queries = static_cast<double>(std::max<size_t>(1, m.loop_queries));
  for (size_t k = 0; k < ranked.size();) {
    const double score = ranked[k].score;
    for (; k < ranked.size() && ranked[k].score == score; ++k) {
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
    p.precision = static_cast<double>(m.true_positives) / static_cast<double>(std::max<size_t>(1, m.true_positives + m.false_positives));
    m.curve.push_back(p);
    if (m.false_positives == 0) m.recall_at_100_precision = p.recall;
  }
  double previous_recall = 0.0;
  for (const PrPoint& p : m.curve) {
    m.average_precision += p.precision * (p.recall - previous_recall);
    previous_recall = p.recall;
    if (p.precision + p.recall > 0.0) m.max_f1 = std::max(m.max_f1, 2 * p.precision * p.recall / (p.precision + p.recall));
  }
  return m;
}

std::string formatScore(double score) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.10g", score);
  return buffer;
}

}  // namespace mild
