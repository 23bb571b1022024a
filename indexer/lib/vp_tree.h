// VpTree: an exact metric index (vantage-point tree, Tam & Lau 2007 section
// 6.2; Yianilos 1993) over items 0..n-1, with exact k-NN, range and ranked
// (incremental, best-first) search under ANY non-negative weighting
//   d_w(x, y) = sum_t w_t d_t(x, y)
// of up to kMaxTerms metrics d_t, from one tree. The terms are supplied as
// callbacks, so the same tree serves the EMD and the spectral terms
// (signature_index.h) and, in tests, plain vectors under L1/L2.
//
//   absl::StatusOr<VpTree> tree = VpTree::Build(n, 2, pair_terms, {1, 1});
//   QuerySpec q; q.weights = {0.5, 2};
//   q.distance = [&](uint32_t i, double* d) { Terms(query, item[i], d); };
//   for (const ItemNeighbor& nb : tree->Knn(q, 10)) Use(nb.item, nb.distance);
//
// Shape: each internal node holds one vantage point (chosen among a few
// random candidates for the largest spread of distances, as NMSLIB does) and
// splits the rest at the median of the build weighting's distance into an
// inner and an outer child; leaves hold buckets of up to leaf_size items.
// Every node stores, for each of its ancestors' vantage points and each
// term, the [min, max] term distance from that point to the items below it,
// and every item each term's distance to each ancestor's vantage point; both
// are by-products of the build. A search under weights w bounds a subtree or
// an item by sum_t w_t L_t, L_t the best triangle-inequality bound of term t
// over the ancestors: each L_t <= d_t, so the sum is <= d_w for every w >= 0
// (intent.h), and it is never looser than the bound of the weighted
// distance itself (sum_t w_t |a_t - b_t| >= |sum_t w_t (a_t - b_t)|).
#ifndef TPR_INDEXER_LIB_VP_TREE_H_
#define TPR_INDEXER_LIB_VP_TREE_H_

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace tpr::index {

// SearchStats counts the work of one search.
struct SearchStats {
  // Full metric evaluations (EMDs), vantage points included.
  int64_t emd_computations = 0;
  // Lower bounds evaluated (QuerySpec::lower_bounds calls, all levels).
  int64_t lower_bounds = 0;
  // Tree nodes expanded.
  int64_t nodes_visited = 0;
};

// ItemNeighbor is one result of a search by item number.
struct ItemNeighbor {
  uint32_t item = 0;
  double distance = 0.0;
};

// VpTreeOptions shapes a VpTree. The paper's tree has fan-out 2 and at most
// two points per node (7.4); we keep fan-out 2 but use leaf buckets, whose
// items are filtered by stored distances at no metric cost.
struct VpTreeOptions {
  // Largest bucket at a leaf. Bucket items cost no metric evaluation until
  // their stored distances and the cheap bounds fail to exclude them, while
  // each internal node visited costs one. Smaller buckets mean fewer bounds
  // per visited bucket and a longer build; 128 was the fastest 10-NN on
  // extracted signatures at 100k (bench_match BM_KnnVpTreeExtractedLeaf,
  // figures in docs/search-cost.md). Default: 128.
  size_t leaf_size = 128;
  // Vantage-point candidates drawn at random per node; the one whose
  // distances to a sample have the largest spread wins. 1 = random choice.
  // Default: 5.
  size_t vantage_candidates = 5;
  // Items each candidate is compared with. Nodes with fewer than
  // 4 * vantage_sample items use 1 candidate (the saving is not worth the
  // distances there). Default: 16.
  size_t vantage_sample = 16;
  // Seed of the candidate draw; the same seed and data give the same tree.
  // Default: 1.
  uint64_t seed = 1;
  // Threads computing distances during the build (the pair metric must then
  // be thread-safe). Default: 1.
  int build_threads = 1;
};

// kMaxTerms: the most terms a tree's distance may have.
inline constexpr size_t kMaxTerms = 3;

// TermVector: one value per term (weights, or term distances); entries
// past a tree's terms() are unused.
using TermVector = std::array<double, kMaxTerms>;

// ValidateWeights returns OK when w[0..terms) are finite and >= 0 with at
// least one > 0, INVALID_ARGUMENT naming the first bad entry otherwise.
// O(terms); thread-safe.
absl::Status ValidateWeights(const TermVector& w, size_t terms);

// PairDistance returns d(item i, item j) >= 0; it must be a metric.
using PairDistance = std::function<double(uint32_t, uint32_t)>;

// PairTerms writes d_t(item i, item j) >= 0 to out[t] for every term t of
// the tree; each d_t must be a metric.
using PairTerms = std::function<void(uint32_t, uint32_t, double* out)>;

// QuerySpec is how a search sees its query.
struct QuerySpec {
  // The search's distance d_w = sum_t weights[t] d_t over the tree's
  // terms: each finite and >= 0, at least one > 0 (ValidateWeights; a
  // precondition of Search). Default: {1, 0, 0}, the first term alone.
  TermVector weights = {1.0, 0.0, 0.0};
  // Required: distance(item, out) writes d_t(query, item) to out[t] for
  // every term t with weights[t] > 0 (the others are not read, and need not
  // be computed). The search's distance is then sum_t weights[t] out[t],
  // summed in term order over the terms with weights[t] > 0. May write NaN
  // for an item whose point is not available; such an item is never
  // returned and its distances are not used for pruning.
  std::function<void(uint32_t item, double* out)> distance;
  // Optional: a cascade of lower bounds on d_w(query, item), cheapest first
  // (for the EMD: the centroid bound, then the relaxed transport bound).
  // Bound l is consulted for an item only when bounds 0..l-1 left it below
  // every answer still to come, so a costly bound runs only where the cheap
  // ones failed; the metric runs only where every bound failed. Each must
  // be <= distance(item) (to rounding; see the deflation in vp_tree.cc).
  // At most 254 bounds.
  std::vector<std::function<double(uint32_t)>> lower_bounds;
  // Optional: false for items that must never be returned (tombstones,
  // filters); their distance is then not computed unless they are vantage
  // points. Called at most once per item per search.
  std::function<bool(uint32_t)> accept;
  // Optional: strict order among items at equal distance. Default: item
  // number.
  std::function<bool(uint32_t, uint32_t)> tie_less;
  // Optional: intra-query parallelism. parallel_for(n, body) runs body(i)
  // for every i in [0, n), possibly concurrently, and returns when all are
  // done. When set and parallel_batch > 1, the search takes up to
  // parallel_batch items from the front of its queue at a time and refines
  // and evaluates them through it; distance and lower_bounds must then be
  // thread-safe. Answers and their order are unchanged; the search may
  // compute up to parallel_batch - 1 distances more than it needs at its
  // end. Default: unset (one thread).
  std::function<void(size_t, const std::function<void(size_t)>&)> parallel_for;
  size_t parallel_batch = 0;
  // Items outside the tree (an unindexed buffer), searched linearly.
  std::vector<uint32_t> extra_items;
  // Only items with distance <= radius are returned. Default: unlimited.
  double radius = std::numeric_limits<double>::infinity();
  // Optional: polled before each step that may compute a distance; once it
  // returns true the search ends (Next() returns nullopt from then on), so a
  // cancelled or late caller stops within one distance (one batch of
  // parallel_batch distances with parallel_for). Default: none.
  std::function<bool()> stop;
  // Optional: a hint, never needed for a correct answer. While the search
  // refines one item it calls prefetch(item, level) for the item it will
  // most likely refine next (the smallest key left), `level` being the
  // first of lower_bounds that item still needs; the caller may start
  // loading what those bounds and the distance will read (e.g. with
  // __builtin_prefetch), so that its memory latency overlaps the current
  // item's arithmetic. Must not change anything a bound or the distance
  // returns; thread-safe when parallel_for is set (not called on that
  // path). Default: none.
  std::function<void(uint32_t item, size_t level)> prefetch;
  // With prefetch set: when the search queues an internal node it also
  // calls prefetch(vp, lower_bounds.size()) for the node's vantage point
  // vp, whose distance it computes if it expands the node (a vantage
  // point's data are otherwise cold: about 9% of a 10-NN over 1M,
  // docs/search-cost.md). Default: false (measured slower at 1M, same
  // document).
  bool prefetch_vantage_points = false;
};

// NeighborCursor yields results in ascending (distance, tie_less) order.
// Not thread-safe; the index it came from must outlive it.
class NeighborCursor {
 public:
  virtual ~NeighborCursor() = default;
  // Next returns the next neighbour, nullopt when none is left.
  virtual std::optional<ItemNeighbor> Next() = 0;
  // stats returns the work done so far.
  virtual const SearchStats& stats() const = 0;
};

// TakeNeighbors returns the first k results of `cursor` (fewer when it runs
// out) and, when stats is non-null, the work done meanwhile: Knn and Range
// of every index. Cost: what k calls of Next cost.
std::vector<ItemNeighbor> TakeNeighbors(NeighborCursor& cursor, size_t k,
                                        SearchStats* stats);

// VpTree is immutable once built; searches on one tree may run concurrently.
class VpTree {
 public:
  // An empty tree (size 0).
  VpTree();
  ~VpTree();
  VpTree(VpTree&&) noexcept;
  VpTree& operator=(VpTree&&) noexcept;

  // Build indexes items 0..n-1 under `terms` term distances (`distance`
  // fills all of them; thread-safe when options.build_threads > 1),
  // splitting on the weighted distance sum_t build_weights[t] d_t. Any
  // search weighting is exact on the tree; one close to build_weights
  // prunes best. Returns INVALID_ARGUMENT for a bad option, terms not in
  // 1..kMaxTerms, invalid build_weights or n >= 2^32 - 1, CANCELLED when
  // *cancel becomes true meanwhile. Cost: about n * (log2(n / leaf_size) +
  // 1) calls of `distance` plus vantage_candidates * vantage_sample per
  // large node; O(n log n x terms) memory.
  static absl::StatusOr<VpTree> Build(
      size_t n, size_t terms, const PairTerms& distance,
      const TermVector& build_weights, const VpTreeOptions& options,
      const std::atomic<bool>* cancel = nullptr);
  // Build of a tree of one term, `distance`, at weight 1.
  static absl::StatusOr<VpTree> Build(
      size_t n, const PairDistance& distance, const VpTreeOptions& options,
      const std::atomic<bool>* cancel = nullptr);

  // terms returns the number of terms (1 for an empty tree built without).
  size_t terms() const;
  // build_weights returns the weighting the tree splits on.
  const TermVector& build_weights() const;

  // size returns the number of items indexed.
  size_t size() const;
  // height returns the number of internal levels on the longest path.
  size_t height() const;
  // node_count returns the number of nodes.
  size_t node_count() const;
  // ItemsInTreeOrder returns every item once, in the tree's node order
  // (depth first: a node's vantage point, then its inner subtree, then its
  // outer one; a leaf's bucket in bucket order), the order in which the
  // tree keeps its stored distances. Items laid out in memory in this
  // order put a bucket's items side by side and a subtree's buckets near
  // each other (SignatureArena). O(n); thread-safe.
  std::vector<uint32_t> ItemsInTreeOrder() const;
  // MemoryBytes returns the heap bytes the tree holds (nodes, stored
  // distances, item tables; not the items' points). O(1).
  size_t MemoryBytes() const;

  // Search starts a ranked search (best-first over node lower bounds, with
  // lazily refined item bounds: stored distance, then the cheap bound, then
  // the metric). Each item is returned as soon as no unexplored node or
  // unrefined item can beat it, so the metric is computed only for items
  // whose bounds are below the last distance returned. spec.distance is
  // required and spec.weights valid for terms() (asserted). The cursor
  // refers to this tree.
  std::unique_ptr<NeighborCursor> Search(QuerySpec spec) const;
  // Knn returns the first min(k, available) results of Search.
  std::vector<ItemNeighbor> Knn(QuerySpec spec, size_t k,
                                SearchStats* stats = nullptr) const;
  // Range returns every result within spec.radius, in order.
  std::vector<ItemNeighbor> Range(QuerySpec spec,
                                  SearchStats* stats = nullptr) const;

  // Serialize returns the tree as versioned, checksummed bytes (structure
  // and stored distances; no points). O(n log n) bytes.
  std::string Serialize() const;
  // Deserialize reads Serialize() bytes. Returns INVALID_ARGUMENT for bytes
  // that are not a VP-tree or of an unknown version, DATA_LOSS for truncated
  // or corrupt ones. Never crashes on arbitrary input.
  static absl::StatusOr<VpTree> Deserialize(absl::string_view bytes);

  struct Node;  // defined in internal/vp_tree_data.h

 private:
  friend class VpTreeBuilder;
  friend class VpCursor;
  friend class VpTreeReader;
  struct Data;
  std::unique_ptr<Data> data_;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_VP_TREE_H_
