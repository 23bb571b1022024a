// Union-find over ids 0..n-1 with path halving, in one flat array: the one
// union-find of the extractor, used by intake (fans, components),
// ComputeMeshStats, the ring sweep (merging wavefronts, 4.6.3) and the
// synthetic shapes' largest-component filter (extractor/synth).
//
//   DisjointSets sets(num_faces);
//   sets.Union(f, g);
//   if (sets.Find(f) == sets.Find(g)) ...
#ifndef TPR_EXTRACTOR_LIB_DISJOINT_SETS_H_
#define TPR_EXTRACTOR_LIB_DISJOINT_SETS_H_

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <vector>

namespace tpr::extract {

// DisjointSets: with Union, the root of a set is its smallest member, so
// results do not depend on the order of unions; Link lets the caller choose
// the root instead. Find is amortized near O(log n) (path halving, no rank).
// Not thread-safe (Find compresses paths).
class DisjointSets {
 public:
  explicit DisjointSets(size_t n = 0) : parent_(n) {
    std::iota(parent_.begin(), parent_.end(), 0);
  }
  // size is the number of ids.
  int64_t size() const { return static_cast<int64_t>(parent_.size()); }
  // Add appends a new singleton set and returns its id (= the old size()).
  int64_t Add() {
    parent_.push_back(size());
    return size() - 1;
  }
  // Find returns the smallest member of x's set.
  int64_t Find(int64_t x) {
    while (parent_[x] != x) {
      parent_[x] = parent_[parent_[x]];
      x = parent_[x];
    }
    return x;
  }
  // Union merges the sets of a and b.
  void Union(int64_t a, int64_t b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }
  // Link makes root `child` a child of root `root`, so that `root` becomes
  // the root of the merged set. Precondition: both are roots (Find(x) == x).
  void Link(int64_t child, int64_t root) { parent_[child] = root; }

 private:
  std::vector<int64_t> parent_;
};

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_DISJOINT_SETS_H_
