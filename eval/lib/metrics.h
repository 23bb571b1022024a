// Retrieval metrics as the shape-retrieval community computes them (Princeton
// Shape Benchmark; SHREC): nearest neighbour, first and second tier,
// E-measure, normalized DCG, mean average precision and the 21-point
// precision-recall curve, per class and averaged over queries.
//
//   std::vector<Query> queries = ...;   // leave-one-out rankings
//   Scores s = Evaluate(labels, queries);
//   std::cout << s.overall.nn << " " << s.overall.ft;
#ifndef TPR_EVAL_LIB_METRICS_H_
#define TPR_EVAL_LIB_METRICS_H_

#include <array>
#include <map>
#include <string>
#include <vector>

namespace tpr::eval {

// Retrieved is one entry of a ranking: the index of a database model and its
// distance to the query.
struct Retrieved {
  int model = 0;
  double distance = 0.0;
};

// Query is one leave-one-out query: the query model's index and the ranking
// of the OTHER models, in any order (Evaluate sorts by distance). Models
// absent from the ranking count as retrieved last (tied among themselves).
struct Query {
  int model = 0;
  std::vector<Retrieved> ranking;
};

// kRecallLevels is the number of points of the precision-recall curve:
// recall 0, 0.05, ..., 1.
inline constexpr int kRecallLevels = 21;

// Metrics holds averages over a set of queries. All in [0, 1].
struct Metrics {
  // Queries averaged (queries whose class has a single model are excluded:
  // they have nothing relevant to retrieve).
  int queries = 0;
  double nn = 0.0;   // relevant at rank 1
  double ft = 0.0;   // recall in the top C-1 (C = the query's class size)
  double st = 0.0;   // recall in the top 2(C-1)
  double e = 0.0;    // E-measure 2PR/(P+R) over the top 32
  double dcg = 0.0;  // DCG / ideal DCG over the whole ranking
  double map = 0.0;  // average precision, averaged
  // Interpolated precision at recall 0, 0.05, ..., 1 (max precision at any
  // recall >= the level), averaged.
  std::array<double, kRecallLevels> pr{};
};

// Scores: over all queries and per class (keyed by label).
struct Scores {
  Metrics overall;
  std::map<std::string, Metrics> per_class;
  // Number of queries excluded because their class has one model.
  int excluded_singletons = 0;
};

// Evaluate scores `queries` against `labels` (labels[i] is model i's class).
//
// Ties: models at exactly equal distance form a group whose order is
// unknown. Each position of the group gets the group's fraction of relevant
// models as its gain. For NN, FT, ST, E and DCG (linear in the gains) this
// is exactly the expected value over all orders of the tied models; for AP
// and the PR curve it is the standard fractional approximation.
//
// Preconditions: every index is in [0, labels.size()), no ranking contains
// its own query or a model twice. Cost O(Q N log N). Thread-safe.
Scores Evaluate(const std::vector<std::string>& labels,
                const std::vector<Query>& queries);

// Objective returns mean(NN, FT, ST, DCG), the one number the tuning
// tools maximize (tpr-eval-local --tune, tpr-tune-intents).
inline double Objective(const Metrics& m) {
  return (m.nn + m.ft + m.st + m.dcg) / 4;
}

// SimilarityMatrix: mean distance between every pair of classes, turned into
// a similarity per row as the paper's Fig. 11 and Tables 2-3 do:
// sim(i, j) = (max_i - D(i, j)) / (max_i - min_i), where min_i and max_i are
// the row's extremes (1 on a row's closest class, 0 on its furthest).
struct SimilarityMatrix {
  std::vector<std::string> classes;                // sorted
  std::vector<std::vector<double>> mean_distance;  // D(i, j)
  std::vector<std::vector<double>> similarity;     // normalized per row
};

// MeanSimilarity builds the matrix from leave-one-out rankings. Self pairs
// are excluded from D(i, i). Cost O(Q N).
SimilarityMatrix MeanSimilarity(const std::vector<std::string>& labels,
                                const std::vector<Query>& queries);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_METRICS_H_
