#include "eval/lib/distance_matrix.h"

#include <utility>

namespace tpr::eval {

std::vector<Query> LeaveOneOutQueries(const DistanceMatrix& d) {
  std::vector<Query> queries;
  queries.reserve(d.size());
  for (size_t i = 0; i < d.size(); ++i) {
    Query q;
    q.model = static_cast<int>(i);
    q.ranking.reserve(d.size() - 1);
    for (size_t j = 0; j < d.size(); ++j) {
      if (j != i) q.ranking.push_back({static_cast<int>(j), d(i, j)});
    }
    queries.push_back(std::move(q));
  }
  return queries;
}

}  // namespace tpr::eval
