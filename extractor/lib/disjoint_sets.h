// Union-find over ids 0..n-1 with path halving, in one flat array: used by
// intake (face components, orientation) and ComputeMeshStats.
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

// DisjointSets: the root of a set is its smallest member, so results do not
// depend on the order of unions. Find is amortized near O(1). Not
// thread-safe (Find compresses paths).
class DisjointSets {
 public:
  explicit DisjointSets(size_t n) : parent_(n) {
    std::iota(parent_.begin(), parent_.end(), 0);
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

 private:
  std::vector<int64_t> parent_;
};

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_DISJOINT_SETS_H_
