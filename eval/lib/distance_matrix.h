// The leave-one-out distance matrix of an evaluation: every pair of models
// under one descriptor's distance, computed in parallel, and the queries
// metrics.h scores from it (each model ranks all the others).
//
//   DistanceMatrix d = PairwiseDistances(n, threads, [&] {
//     return [&, solver = EmdSolver()](size_t i, size_t j) mutable {
//       return solver.Distance(sig[i], sig[j]); };
//   });
//   Scores s = Evaluate(labels, LeaveOneOutQueries(d));
#ifndef TPR_EVAL_LIB_DISTANCE_MATRIX_H_
#define TPR_EVAL_LIB_DISTANCE_MATRIX_H_

#include <cassert>
#include <chrono>
#include <cstddef>
#include <string>
#include <vector>

#include "common/parallel.h"
#include "eval/lib/metrics.h"

namespace tpr::eval {

// DistanceMatrix is a symmetric n x n matrix of distances with a zero
// diagonal, stored flat (row-major).
class DistanceMatrix {
 public:
  explicit DistanceMatrix(size_t n = 0) : n_(n), d_(n * n, 0.0) {}
  size_t size() const { return n_; }
  // Returns d(i, j). Precondition: i, j < size().
  double operator()(size_t i, size_t j) const {
    assert(i < n_ && j < n_);
    return d_[i * n_ + j];
  }
  // Set stores d(i, j) = d(j, i) = x. Not thread-safe for the same pair.
  void Set(size_t i, size_t j, double x) {
    assert(i < n_ && j < n_);
    d_[i * n_ + j] = x;
    d_[j * n_ + i] = x;
  }

 private:
  size_t n_;
  std::vector<double> d_;
};

// PairwiseDistances returns d(i, j) for every pair i < j < n (mirrored),
// rows spread over `threads` threads (ParallelForEachWorker).
// make_distance() is called once per worker thread and returns that
// worker's callable double(size_t i, size_t j), so a solver with scratch
// space is never shared. `thread_ms`, if not null, receives the sum of the
// workers' busy time in milliseconds (per-pair costs that do not depend on
// the thread count). Cost: n(n-1)/2 distance calls. The callables must be
// symmetric in (i, j) for the matrix to mean anything.
template <typename MakeDistance>
DistanceMatrix PairwiseDistances(size_t n, int threads,
                                 MakeDistance make_distance,
                                 double* thread_ms = nullptr) {
  using Clock = std::chrono::steady_clock;
  DistanceMatrix d(n);
  // One slot per row: rows are disjoint, so no lock is needed.
  std::vector<double> row_ms(n, 0.0);
  common::ParallelForEachWorker(n, threads, [&] {
    return [&, distance = make_distance()](size_t i) mutable {
      const Clock::time_point start = Clock::now();
      for (size_t j = i + 1; j < n; ++j) d.Set(i, j, distance(i, j));
      row_ms[i] =
          std::chrono::duration<double, std::milli>(Clock::now() - start)
              .count();
    };
  });
  if (thread_ms != nullptr) {
    *thread_ms = 0.0;
    for (double t : row_ms) *thread_ms += t;
  }
  return d;
}

// LeaveOneOutQueries returns one Query per model i of `d` (model = i), its
// ranking holding every other model j at distance d(i, j). O(n^2).
std::vector<Query> LeaveOneOutQueries(const DistanceMatrix& d);

// ClassSeparation: mean distance between two distinct models of one class
// and of different classes, over every pair (the measure of how well
// a distance separates similar-skeleton classes).
struct ClassSeparation {
  double within = 0.0, between = 0.0;
  // within / between (lower separates better); 0 when there is no pair
  // of different classes or their mean distance is 0.
  double Ratio() const { return between > 0.0 ? within / between : 0.0; }
};

// Separation returns the ClassSeparation of `d` (labels[i]: model i's
// class). Precondition: labels.size() == d.size(). O(n^2); thread-safe.
ClassSeparation Separation(const std::vector<std::string>& labels,
                           const DistanceMatrix& d);

// Separation over the (query, retrieved) pairs of `queries` (each pair of
// a full leave-one-out evaluation is then counted twice, which leaves the
// means as above): what `tpr eval` measures through the services. O(pairs).
ClassSeparation Separation(const std::vector<std::string>& labels,
                           const std::vector<Query>& queries);

// Restrict returns the submatrix of `d` over positions `members` (in that
// order). Precondition: every member < d.size(). O(members^2).
DistanceMatrix Restrict(const DistanceMatrix& d,
                        const std::vector<size_t>& members);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_DISTANCE_MATRIX_H_
