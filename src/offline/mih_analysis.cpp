#include "mild_lcd/offline/mih_analysis.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "mild_lcd/common/errors.hpp"

namespace mild {
namespace {

using Real = long double;  // 80-bit extended: exponent range to 2^16383, so 256! and 64^256 fit

void checkArguments(int r, int m, int bits) {
  if (bits < 8 || bits > kMaxDescriptorBits) {
    throw InvalidInput("descriptor width must be in [8, " + std::to_string(kMaxDescriptorBits) + "] bits, got " +
                       std::to_string(bits));
  }
  if (m < 1 || m > bits) {
    throw InvalidInput("m (hash tables) must be in [1, " + std::to_string(bits) + "], got " + std::to_string(m));
  }
  if (r < 0) throw InvalidInput("r (probe radius) must be >= 0, got " + std::to_string(r));
}

// Substring lengths as SubstringLayout cuts them: the first (bits mod m) are one bit longer.
std::vector<int> substringLengths(int m, int bits) {
  std::vector<int> lengths(m, bits / m);
  for (int t = 0; t < bits % m; ++t) ++lengths[t];
  return lengths;
}

// Truncated product of polynomials in x (degree <= their size - 1).
std::vector<Real> multiply(const std::vector<Real>& a, const std::vector<Real>& b) {
  const int top = static_cast<int>(a.size()) - 1;
  std::vector<Real> out(a.size(), 0.0L);
  for (int i = 0; i <= top; ++i) {
    if (a[i] == 0.0L) continue;
    for (int j = 0; i + j <= top; ++j) out[i + j] += a[i] * b[j];
  }
  return out;
}

std::vector<Real> power(std::vector<Real> base, int exponent) {
  std::vector<Real> result(base.size(), 0.0L);
  result[0] = 1.0L;
  while (exponent > 0) {  // square-and-multiply: log2(m) products instead of m
    if (exponent & 1) result = multiply(result, base);
    exponent >>= 1;
    if (exponent > 0) base = multiply(base, base);
  }
  return result;
}

// Pascal's triangle up to n = 512: sums only, so every entry is correct to long double precision.
Real binomial(int n, int k) {
  static const std::vector<std::vector<Real>> table = [] {
    std::vector<std::vector<Real>> t(kMaxDescriptorBits + 1);
    for (int i = 0; i <= kMaxDescriptorBits; ++i) {
      t[i].assign(i + 1, 1.0L);
      for (int j = 1; j < i; ++j) t[i][j] = t[i - 1][j - 1] + t[i - 1][j];
    }
    return t;
  }();
  if (n < 0 || n > kMaxDescriptorBits || k < 0 || k > n) return 0.0L;
  return table[n][k];
}

// P(every substring holds more than r of the d differing bits), for every d.
std::vector<Real> allAboveRadius(int r, int m, BitModel model, int bits) {
  std::vector<Real> out(bits + 1, 0.0L);
  if (model == BitModel::kPaper) {
    // d! / m^d [x^d] (sum_{k>r} x^k/k!)^m
    std::vector<Real> bin(bits + 1, 0.0L);
    Real inverse_factorial = 1.0L;
    for (int k = 0; k <= bits; ++k) {
      if (k > 0) inverse_factorial /= k;
      if (k > r) bin[k] = inverse_factorial;
    }
    const std::vector<Real> all = power(bin, m);
    Real scale = 1.0L;  // d! / m^d, built up term by term to stay in range
    for (int d = 0; d <= bits; ++d) {
      if (d > 0) scale *= static_cast<Real>(d) / m;
      out[d] = all[d] * scale;
    }
  } else {
    // [x^d] prod_t sum_{k>r} C(l_t, k) x^k / C(bits, d); lengths take two values at most.
    std::vector<Real> all(bits + 1, 0.0L);
    all[0] = 1.0L;
    const int longer = bits % m;
    for (const auto& [length, count] : {std::pair<int, int>{bits / m + 1, longer}, {bits / m, m - longer}}) {
      if (count == 0) continue;
      std::vector<Real> substring(bits + 1, 0.0L);
      for (int k = r + 1; k <= length; ++k) substring[k] = binomial(length, k);
      all = multiply(all, power(substring, count));
    }
    for (int d = 0; d <= bits; ++d) out[d] = all[d] / binomial(bits, d);
  }
  return out;
}

}  // namespace

BitModel bitModelFromName(const std::string& name) {
  if (name == "paper") return BitModel::kPaper;
  if (name == "exact") return BitModel::kExact;
  throw InvalidInput("bit model must be 'paper' or 'exact', got '" + name + "'");
}

std::string bitModelName(BitModel model) { return model == BitModel::kPaper ? "paper" : "exact"; }

std::vector<double> recallCurve(int r, int m, BitModel model, int bits) {
  checkArguments(r, m, bits);
  const std::vector<Real> miss = allAboveRadius(r, m, model, bits);
  std::vector<double> recall(bits + 1);
  for (int d = 0; d <= bits; ++d) {
    recall[d] = static_cast<double>(std::clamp(1.0L - miss[d], 0.0L, 1.0L));
  }
  return recall;
}

double recallProbability(int r, int m, int d, BitModel model, int bits) {
  if (d < 0 || d > bits) throw InvalidInput("d must be in [0, " + std::to_string(bits) + "], got " + std::to_string(d));
  return recallCurve(r, m, model, bits)[d];
}

double recallByInclusionExclusion(int m, int d) {
  checkArguments(0, m, kMaxDescriptorBits);
  Real sum = 0.0L;
  for (int j = 0; j <= m; ++j) {
    const Real term = binomial(m, j) * std::pow(1.0L - static_cast<Real>(j) / m, d);
    sum += (j % 2 == 0) ? term : -term;
  }
  return static_cast<double>(1.0L - sum);
}

DistancePrior DistancePrior::normal(double mean, double stddev, int bits) {
  if (!(stddev > 0.0) || !std::isfinite(stddev) || !std::isfinite(mean)) {
    throw InvalidInput("a normal prior needs a finite mean and a positive standard deviation");
  }
  checkArguments(0, 1, bits);
  std::vector<double> counts(bits + 1);
  for (int d = 0; d <= bits; ++d) counts[d] = std::exp(-0.5 * std::pow((d - mean) / stddev, 2));
  return fromCounts(counts, bits);
}

DistancePrior DistancePrior::fromCounts(const std::vector<double>& counts, int bits) {
  checkArguments(0, 1, bits);
  if (counts.size() > static_cast<size_t>(bits + 1)) {
    throw InvalidInput("a distance prior of " + std::to_string(bits) + "-bit descriptors covers d = 0.." +
                       std::to_string(bits) + " only");
  }
  double total = 0.0;
  for (double c : counts) {
    if (!(c >= 0.0) || !std::isfinite(c)) throw InvalidInput("distance counts must be finite and non-negative");
    total += c;
  }
  if (!(total > 0.0)) throw InvalidInput("distance counts are all zero: nothing to build a prior from");
  DistancePrior prior;
  prior.p.assign(static_cast<size_t>(bits) + 1, 0.0);
  for (size_t d = 0; d < counts.size(); ++d) prior.p[d] = counts[d] / total;
  return prior;
}

double DistancePrior::mean() const {
  double m = 0.0;
  for (size_t d = 0; d < p.size(); ++d) m += static_cast<double>(d) * p[d];
  return m;
}

DistancePrior paperInlierPrior() { return DistancePrior::normal(32.0, 10.0); }
DistancePrior paperOutlierPrior() { return DistancePrior::normal(128.0, 20.0); }

double fixedCost(int m, int bits) {
  checkArguments(0, m, bits);
  double total = 0.0;
  for (int length : substringLengths(m, bits)) total += std::ldexp(1.0, length);
  return total;
}

MihCost analyse(int r, int m, const DistancePrior& inliers, const DistancePrior& outliers, BitModel model) {
  const int bits = inliers.bits();
  if (outliers.bits() != bits || bits < 1) {
    throw InvalidInput("inlier and outlier priors must cover the same distances (d = 0..bits)");
  }
  const std::vector<double> recall = recallCurve(r, m, model, bits);
  MihCost cost;
  cost.m = m;
  cost.r = r;
  for (int d = 0; d <= bits; ++d) {
    cost.accuracy += recall[d] * inliers.p[d];
    cost.complexity += recall[d] * outliers.p[d];
  }
  cost.fixed_cost = fixedCost(m, bits);
  for (int length : substringLengths(m, bits)) {
    for (int k = 0; k <= std::min(r, length); ++k) cost.probes += static_cast<double>(binomial(length, k));
  }
  return cost;
}

std::vector<MihCost> analyseGrid(int m_min, int m_max, int r_min, int r_max, const DistancePrior& inliers,
                                 const DistancePrior& outliers, BitModel model) {
  if (m_min > m_max || r_min > r_max) throw InvalidInput("empty range of m or r");
  std::vector<MihCost> grid;
  for (int r = r_min; r <= r_max; ++r) {
    for (int m = m_min; m <= m_max; ++m) grid.push_back(analyse(r, m, inliers, outliers, model));
  }
  return grid;
}

std::vector<MihCost> smallestTablesReaching(const std::vector<MihCost>& grid, double min_accuracy) {
  std::vector<MihCost> out;
  for (const MihCost& c : grid) {
    if (c.accuracy < min_accuracy) continue;
    auto same_r = std::find_if(out.begin(), out.end(), [&](const MihCost& o) { return o.r == c.r; });
    if (same_r == out.end()) {
      out.push_back(c);
    } else if (c.m < same_r->m) {
      *same_r = c;
    }
  }
  std::sort(out.begin(), out.end(), [](const MihCost& a, const MihCost& b) { return a.r < b.r; });
  return out;
}

Recommendation recommend(const std::vector<MihCost>& grid, double min_accuracy, bool online, double database_features) {
  if (online && !(database_features >= 0.0)) throw InvalidInput("the database size must be >= 0 features");
  Recommendation rec;
  rec.candidates = smallestTablesReaching(grid, min_accuracy);
  if (rec.candidates.empty()) {
    throw InvalidInput("no (m, r) in the range reaches accuracy " + std::to_string(min_accuracy) +
                       "; widen --m-range or --r-range");
  }
  auto cost_of = [&](const MihCost& c) {
    return online ? c.complexity * database_features + c.fixed_cost : c.complexity;
  };
  rec.choice = *std::min_element(rec.candidates.begin(), rec.candidates.end(),
                                 [&](const MihCost& a, const MihCost& b) { return cost_of(a) < cost_of(b); });
  rec.cost = cost_of(rec.choice);
  std::ostringstream why;
  why.precision(3);
  why << "(m, r) = (" << rec.choice.m << ", " << rec.choice.r << "): accuracy " << rec.choice.accuracy
      << " >= " << min_accuracy << " at the least " << (online ? "online" : "offline") << " cost ";
  if (online) {
    why << "E*N + E_fixed = " << rec.choice.complexity << " * " << database_features << " + " << rec.choice.fixed_cost;
  } else {
    why << "E = " << rec.choice.complexity;
  }
  why << " among the smallest m per r reaching it";
  rec.explanation = why.str();
  return rec;
}

}  // namespace mild
