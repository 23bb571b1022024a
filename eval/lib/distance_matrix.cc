#include "eval/lib/distance_matrix.h"

#include <cstdint>
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

ClassSeparation Separation(const std::vector<std::string>& labels,
                           const DistanceMatrix& d) {
  ClassSeparation s;
  int64_t within = 0, between = 0;
  for (size_t i = 0; i < d.size(); ++i) {
    for (size_t j = i + 1; j < d.size(); ++j) {
      if (labels[i] == labels[j]) {
        s.within += d(i, j);
        ++within;
      } else {
        s.between += d(i, j);
        ++between;
      }
    }
  }
  if (within > 0) s.within /= static_cast<double>(within);
  if (between > 0) s.between /= static_cast<double>(between);
  return s;
}

ClassSeparation Separation(const std::vector<std::string>& labels,
                           const std::vector<Query>& queries) {
  ClassSeparation s;
  int64_t within = 0, between = 0;
  for (const Query& q : queries) {
    for (const Retrieved& r : q.ranking) {
      if (labels[q.model] == labels[r.model]) {
        s.within += r.distance;
        ++within;
      } else {
        s.between += r.distance;
        ++between;
      }
    }
  }
  if (within > 0) s.within /= static_cast<double>(within);
  if (between > 0) s.between /= static_cast<double>(between);
  return s;
}

DistanceMatrix Restrict(const DistanceMatrix& d,
                        const std::vector<size_t>& members) {
  DistanceMatrix out(members.size());
  for (size_t a = 0; a < members.size(); ++a) {
    for (size_t b = a + 1; b < members.size(); ++b)
      out.Set(a, b, d(members[a], members[b]));
  }
  return out;
}

}  // namespace tpr::eval
