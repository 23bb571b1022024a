// BruteForceIndex: the exact k-NN oracle (Tam & Lau 2007 section 6.2's
// VP-tree answers must equal it), with VpTree's search interface: it
// computes every distance and sorts. Tests compare the tree with it and
// benchmarks measure the tree against it.
//
//   BruteForceIndex oracle(n);
//   QuerySpec q;
//   q.distance = [&](uint32_t i, double* d) { d[0] = Dist(query, item[i]); };
//   std::vector<ItemNeighbor> exact = oracle.Knn(q, 10);
#ifndef TPR_INDEXER_LIB_BRUTE_FORCE_INDEX_H_
#define TPR_INDEXER_LIB_BRUTE_FORCE_INDEX_H_

#include <cstddef>
#include <memory>
#include <vector>

#include "indexer/lib/vp_tree.h"

namespace tpr::index {

// BruteForceIndex searches items 0..n-1 (plus spec.extra_items) linearly.
// Stateless apart from n; searches may run concurrently.
class BruteForceIndex {
 public:
  explicit BruteForceIndex(size_t n) : n_(n) {}
  // size returns n.
  size_t size() const { return n_; }
  // Search computes d_w = sum_t spec.weights[t] d_t (in term order, over
  // the terms with weights[t] > 0) from spec.distance for every accepted
  // item up front (O(n) metric calls; spec.lower_bounds is ignored), drops
  // NaN and those beyond spec.radius, and sorts by (distance, tie_less):
  // O(n log n).
  std::unique_ptr<NeighborCursor> Search(QuerySpec spec) const;
  // Knn returns the first min(k, available) results of Search.
  std::vector<ItemNeighbor> Knn(QuerySpec spec, size_t k,
                                SearchStats* stats = nullptr) const;
  // Range returns every result within spec.radius, in order.
  std::vector<ItemNeighbor> Range(QuerySpec spec,
                                  SearchStats* stats = nullptr) const;

 private:
  size_t n_;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_BRUTE_FORCE_INDEX_H_
