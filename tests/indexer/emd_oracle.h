// Independent EMD oracle for tests and the benchmark peer: LEMON's
// NetworkSimplex (Debian liblemon-dev, Boost licence) on the same ground
// distances.
//
//   LemonEmd oracle;
//   double expected = oracle.Distance(p, q);     // reuses the graph per size
//   EXPECT_NEAR(Emd(p, q), expected, 1e-6 * expected);
//
// Masses are scaled to integers (2^40 per unit of mass, rounding fixed on
// the largest entry so that supply equals demand exactly): LEMON's
// EQ-supply problem is infeasible unless the totals match bit for bit, which
// doubles summed in different orders do not. Costs are scaled to integers
// too (the largest to 2^40): with double costs LEMON's pivot loop compares
// reduced costs with 0 exactly and can cycle forever on rounding noise (seen
// here on a 30 x 30 pair). Both roundings change the EMD by about 1e-12 of
// the largest ground distance.
#ifndef TPR_TESTS_INDEXER_EMD_ORACLE_H_
#define TPR_TESTS_INDEXER_EMD_ORACLE_H_

#include <lemon/list_graph.h>
#include <lemon/network_simplex.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include "indexer/lib/ground_distance.h"

namespace tpr::index::testing {

class LemonEmd {
 public:
  using Graph = lemon::ListDigraph;
  using Simplex = lemon::NetworkSimplex<Graph, int64_t, int64_t>;

  // Distance returns the EMD of a and b by LEMON on the ground distances of
  // GroundDistanceMatrix, or -1 if LEMON does not report OPTIMAL (never
  // expected).
  double Distance(const PreparedSignature& a, const PreparedSignature& b) {
    const int n = a.size();
    const int m = b.size();
    Setup(n, m);
    matrix_.resize(static_cast<size_t>(n) * b.stride());
    GroundDistanceMatrix(a, b, matrix_.data(), b.stride());
    costs_.resize(static_cast<size_t>(n) * m);
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < m; ++j) {
        costs_[static_cast<size_t>(i) * m + j] =
            matrix_[static_cast<size_t>(i) * b.stride() + j];
      }
    }
    return Run(a, b);
  }

  // DistanceScalar is Distance with the ground distances computed one
  // by one by the scalar GroundDistance (independent of the matrix kernel).
  double DistanceScalar(const PreparedSignature& a,
                        const PreparedSignature& b) {
    const int n = a.size();
    const int m = b.size();
    Setup(n, m);
    costs_.resize(static_cast<size_t>(n) * m);
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < m; ++j) {
        costs_[static_cast<size_t>(i) * m + j] = GroundDistance(a, i, b, j);
      }
    }
    return Run(a, b);
  }

  // DistanceWithCosts returns the EMD of a's and b's masses under the given
  // ground distances (a.size() x b.size(), row-major), e.g. Eq. 7 in double
  // from the raw signatures (eq7_oracle.h).
  double DistanceWithCosts(const PreparedSignature& a,
                           const PreparedSignature& b,
                           const std::vector<double>& costs) {
    Setup(a.size(), b.size());
    costs_ = costs;
    return Run(a, b);
  }

 private:
  static std::vector<int64_t> Scale(const PreparedSignature& s, int64_t total) {
    constexpr double kUnit = 1099511627776.0;  // 2^40
    std::vector<int64_t> q(static_cast<size_t>(s.size()));
    int64_t sum = 0;
    size_t largest = 0;
    for (int i = 0; i < s.size(); ++i) {
      q[i] = std::llround(s.weight(i) * kUnit);
      sum += q[i];
      if (q[i] > q[largest]) largest = static_cast<size_t>(i);
    }
    q[largest] += (total > 0 ? total : static_cast<int64_t>(kUnit)) - sum;
    return q;
  }

  void Setup(int n, int m) {
    if (n == n_ && m == m_) return;
    n_ = n;
    m_ = m;
    simplex_.reset();
    cost_.reset();
    supply_.reset();
    graph_ = std::make_unique<Graph>();
    nodes_.clear();
    arcs_.clear();
    for (int v = 0; v < n + m; ++v) nodes_.push_back(graph_->addNode());
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < m; ++j) {
        arcs_.push_back(graph_->addArc(nodes_[i], nodes_[n + j]));
      }
    }
    cost_ = std::make_unique<Graph::ArcMap<int64_t>>(*graph_);
    supply_ = std::make_unique<Graph::NodeMap<int64_t>>(*graph_);
    simplex_ = std::make_unique<Simplex>(*graph_);
  }

  double Run(const PreparedSignature& a, const PreparedSignature& b) {
    double max_cost = 0.0;
    for (double c : costs_) max_cost = std::max(max_cost, c);
    if (max_cost == 0.0) return 0.0;
    const double cost_unit = 1099511627776.0 / max_cost;  // largest -> 2^40
    for (size_t k = 0; k < costs_.size(); ++k) {
      (*cost_)[arcs_[k]] = std::llround(costs_[k] * cost_unit);
    }
    const std::vector<int64_t> qa = Scale(a, 0);
    int64_t total = 0;
    for (int64_t x : qa) total += x;
    const std::vector<int64_t> qb = Scale(b, total);
    for (int i = 0; i < n_; ++i) (*supply_)[nodes_[i]] = qa[i];
    for (int j = 0; j < m_; ++j) (*supply_)[nodes_[n_ + j]] = -qb[j];
    // The graph is unchanged since construction: resetParams suffices.
    simplex_->resetParams();
    simplex_->costMap(*cost_).supplyMap(*supply_);
    if (simplex_->run() != Simplex::OPTIMAL) return -1.0;
    return simplex_->totalCost<double>() /
           (static_cast<double>(total) * cost_unit);
  }

  int n_ = -1;
  int m_ = -1;
  std::unique_ptr<Graph> graph_;
  std::vector<Graph::Node> nodes_;
  std::vector<Graph::Arc> arcs_;
  std::unique_ptr<Graph::ArcMap<int64_t>> cost_;
  std::vector<double> costs_;
  std::unique_ptr<Graph::NodeMap<int64_t>> supply_;
  std::unique_ptr<Simplex> simplex_;
  std::vector<double> matrix_;
};

}  // namespace tpr::index::testing

#endif  // TPR_TESTS_INDEXER_EMD_ORACLE_H_
