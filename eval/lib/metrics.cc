#include "eval/lib/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <unordered_set>

namespace tpr::eval {
namespace {

// Gains per rank position (1 relevant, 0 not; fractional inside tie groups)
// for one query, over all N-1 other models.
std::vector<double> TieAwareGains(const std::vector<std::string>& labels,
                                  const Query& query) {
  const std::string& cls = labels[query.model];
  std::vector<Retrieved> ranking = query.ranking;
  std::sort(ranking.begin(), ranking.end(),
            [](const Retrieved& a, const Retrieved& b) {
              return a.distance < b.distance;
            });
  // Models missing from the ranking are appended as one last tie group.
  std::unordered_set<int> seen;
  for (const Retrieved& r : ranking) seen.insert(r.model);
  const double kMissing = std::numeric_limits<double>::infinity();
  for (int m = 0; m < static_cast<int>(labels.size()); ++m) {
    if (m != query.model && !seen.count(m)) ranking.push_back({m, kMissing});
  }
  std::vector<double> gains(ranking.size(), 0.0);
  size_t begin = 0;
  while (begin < ranking.size()) {
    size_t end = begin + 1;
    while (end < ranking.size() &&
           ranking[end].distance == ranking[begin].distance) {
      ++end;
    }
    int relevant = 0;
    for (size_t i = begin; i < end; ++i) {
      relevant += labels[ranking[i].model] == cls;
    }
    const double gain = static_cast<double>(relevant) / (end - begin);
    for (size_t i = begin; i < end; ++i) gains[i] = gain;
    begin = end;
  }
  return gains;
}

// Sum of gains over the first `k` positions.
double RelevantInTop(const std::vector<double>& gains, size_t k) {
  double sum = 0.0;
  for (size_t i = 0; i < std::min(k, gains.size()); ++i) sum += gains[i];
  return sum;
}

Metrics ScoreOne(const std::vector<double>& gains, int relevant) {
  Metrics m;
  m.queries = 1;
  const double r = relevant;
  m.nn = gains.empty() ? 0.0 : gains[0];
  m.ft = RelevantInTop(gains, relevant) / r;
  m.st = RelevantInTop(gains, 2 * static_cast<size_t>(relevant)) / r;
  // E-measure over the top 32 (PSB): P = rel/32, R = rel/(C-1).
  const double rel32 = RelevantInTop(gains, 32);
  const double p32 = rel32 / 32.0, r32 = rel32 / r;
  m.e = (p32 + r32) > 0.0 ? 2.0 * p32 * r32 / (p32 + r32) : 0.0;
  // DCG as in the SHREC'11 evaluation code: DCG_1 = G_1,
  // DCG_i = DCG_{i-1} + G_i / log2(i); normalized by the ideal ranking.
  double dcg = 0.0, ideal = 0.0;
  for (size_t i = 0; i < gains.size(); ++i) {
    const double discount = i == 0 ? 1.0 : 1.0 / std::log2(i + 1.0);
    dcg += gains[i] * discount;
    if (static_cast<int>(i) < relevant) ideal += discount;
  }
  m.dcg = dcg / ideal;
  // Average precision and precision at each recall reached.
  double found = 0.0, ap = 0.0;
  std::vector<double> precision(gains.size()), recall(gains.size());
  for (size_t i = 0; i < gains.size(); ++i) {
    found += gains[i];
    precision[i] = found / (i + 1.0);
    recall[i] = found / r;
    ap += gains[i] * precision[i];
  }
  m.map = ap / r;
  // Interpolated precision: max precision at any recall >= level.
  for (int level = 0; level < kRecallLevels; ++level) {
    const double target = level / (kRecallLevels - 1.0);
    double best = 0.0;
    for (size_t i = 0; i < gains.size(); ++i) {
      if (recall[i] + 1e-12 >= target) best = std::max(best, precision[i]);
    }
    m.pr[level] = best;
  }
  return m;
}

void Accumulate(const Metrics& one, Metrics* sum) {
  sum->queries += one.queries;
  sum->nn += one.nn;
  sum->ft += one.ft;
  sum->st += one.st;
  sum->e += one.e;
  sum->dcg += one.dcg;
  sum->map += one.map;
  for (int i = 0; i < kRecallLevels; ++i) sum->pr[i] += one.pr[i];
}

void Average(Metrics* m) {
  if (m->queries == 0) return;
  const double n = m->queries;
  m->nn /= n;
  m->ft /= n;
  m->st /= n;
  m->e /= n;
  m->dcg /= n;
  m->map /= n;
  for (double& p : m->pr) p /= n;
}

}  // namespace

Scores Evaluate(const std::vector<std::string>& labels,
                const std::vector<Query>& queries) {
  std::unordered_map<std::string, int> class_size;
  for (const std::string& l : labels) ++class_size[l];
  Scores scores;
  for (const Query& q : queries) {
    const std::string& cls = labels[q.model];
    const int relevant = class_size[cls] - 1;
    if (relevant <= 0) {
      ++scores.excluded_singletons;
      continue;
    }
    const Metrics one = ScoreOne(TieAwareGains(labels, q), relevant);
    Accumulate(one, &scores.overall);
    Accumulate(one, &scores.per_class[cls]);
  }
  Average(&scores.overall);
  for (auto& [cls, m] : scores.per_class) Average(&m);
  return scores;
}

SimilarityMatrix MeanSimilarity(const std::vector<std::string>& labels,
                                const std::vector<Query>& queries) {
  SimilarityMatrix out;
  std::map<std::string, int> index;
  for (const std::string& l : labels) index.emplace(l, 0);
  for (auto& [cls, i] : index) {
    i = static_cast<int>(out.classes.size());
    out.classes.push_back(cls);
  }
  const size_t c = out.classes.size();
  std::vector<std::vector<double>> sum(c, std::vector<double>(c, 0.0));
  std::vector<std::vector<double>> count(c, std::vector<double>(c, 0.0));
  for (const Query& q : queries) {
    const int a = index[labels[q.model]];
    for (const Retrieved& r : q.ranking) {
      if (r.model == q.model || !std::isfinite(r.distance)) continue;
      const int b = index[labels[r.model]];
      sum[a][b] += r.distance;
      count[a][b] += 1.0;
    }
  }
  out.mean_distance.assign(c, std::vector<double>(c, 0.0));
  out.similarity.assign(c, std::vector<double>(c, 0.0));
  for (size_t i = 0; i < c; ++i) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (size_t j = 0; j < c; ++j) {
      out.mean_distance[i][j] = count[i][j] > 0
                                    ? sum[i][j] / count[i][j]
                                    : std::numeric_limits<double>::quiet_NaN();
      if (count[i][j] > 0) {
        lo = std::min(lo, out.mean_distance[i][j]);
        hi = std::max(hi, out.mean_distance[i][j]);
      }
    }
    for (size_t j = 0; j < c; ++j) {
      const double d = out.mean_distance[i][j];
      out.similarity[i][j] = !std::isfinite(d) ? 0.0
                             : hi > lo         ? (hi - d) / (hi - lo)
                                               : 1.0;
    }
  }
  return out;
}

}  // namespace tpr::eval
