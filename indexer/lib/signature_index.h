// SignatureIndex: the service-facing similarity index over TPR signatures.
// Signatures are compared with a non-negative weighting of three terms
// (metric.h, intent.h): the Earth Mover's Distance of Tam & Lau 2007
// (section 6.1), the spectral term and the heat-trace term; they are indexed
// with one VP-tree (section 6.2, vp_tree.h) that keeps each term's bounds
// apart, so every weighting (every intent, every Ranking) is searched exactly
// from it. Inserts and deletes go to a small unindexed buffer plus
// tombstones until the next rebuild, so every answer stays exact.
//
//   SignatureIndex index(IndexOptions{});
//   TPR_RETURN_IF_ERROR(index.Upsert("dog-3", signature));
//   for (const Neighbor& n : index.Knn(query, 10)) Show(n.id, n.distance);
#ifndef TPR_INDEXER_LIB_SIGNATURE_INDEX_H_
#define TPR_INDEXER_LIB_SIGNATURE_INDEX_H_

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/intent.h"
#include "indexer/lib/signature.h"
#include "indexer/lib/vp_tree.h"

namespace tpr::index {

// SearchStats (declared in vp_tree.h) counts the work of one search: full
// EMDs computed, cheap EMD lower bounds computed, tree nodes visited.

// Neighbor is one search result: a model id and its distance to the query
// under the search's weighting.
struct Neighbor {
  std::string id;
  double distance = 0.0;
};

// IndexOptions configures a SignatureIndex.
struct IndexOptions {
  // The ground distance of Eq. 7 (weights W1..W4) and the spectral and
  // heat-trace embeddings; every signature in one index is prepared with the
  // same options. Default: GroundDistanceOptions{}.
  GroundDistanceOptions ground;
  // The weighting the VP-tree splits on (its own distance, and that of Knn).
  // Searches under any valid weighting are exact; those under this one
  // prune best. Must be valid (ValidateTermWeights). Default:
  // IntentWeights(Intent::kBalanced), the default of every search.
  TermWeights build_weights = IntentWeights(Intent::kBalanced);
  // Number of buffered inserts plus tombstoned tree entries past which the
  // index rebuilds its tree. The buffer is searched linearly (one EMD lower
  // bound per entry and an EMD where the bound cannot exclude it), so the
  // threshold bounds the extra cost per query. Default: 512.
  size_t rebuild_threshold = 512;
  // When true, crossing rebuild_threshold starts Rebuild() on a background
  // thread (one at a time; searches and writes continue meanwhile). When
  // false, the owner calls Rebuild(); results are exact either way.
  // Default: true.
  bool background_rebuild = true;
  // Tree shape (leaf bucket size, vantage-point candidates, seed); see
  // VpTreeOptions. Default: VpTreeOptions{}.
  VpTreeOptions tree;
  // Whether searches refine the centroid bound with the relaxed transport
  // bound with capacities (ConstrainedTransportBound32, emd.h) before
  // computing an EMD. Results are identical either way; off only to
  // measure what it saves (bench_match). Default: true.
  bool relaxed_bound = true;
  // Threads one search may use for its bounds and EMDs (intra-query
  // parallelism, see QuerySpec::parallel_for): the index keeps a task arena
  // of this many threads shared by all its searches (the calling thread
  // takes part). Answers and their order do not depend on it. 1 = every
  // search runs on its calling thread. Default: 1.
  int search_threads = 1;
  // Items one parallel step refines at once (QuerySpec::parallel_batch);
  // 0 = 2 x search_threads. Default: 0.
  size_t search_batch = 0;
};

// ValidateIndexOptions returns OK when `options` can build an index:
// INVALID_ARGUMENT naming the field (ground: ValidateOptions; build_weights:
// ValidateTermWeights) otherwise. O(1); thread-safe.
absl::Status ValidateIndexOptions(const IndexOptions& options);

// SignatureIndex maps ids to signatures and answers exact searches.
// Thread-safety: every method may be called concurrently. A search works on
// an immutable snapshot (the tree, shared, plus a copy of the small buffer
// and tombstone set), so writers never wait for searches and a search never
// sees half a write.
class SignatureIndex {
 public:
  // Cursor yields neighbours one at a time in ascending (distance, id)
  // order, each as soon as it is certain; a caller may stop at any time.
  // A cursor keeps its snapshot alive and is independent of later writes.
  // Not thread-safe itself: one caller at a time (any thread).
  class Cursor {
   public:
    virtual ~Cursor() = default;
    // Next returns the next neighbour, or nullopt when none is left (all
    // items within the radius and passing the filter have been returned).
    // Cost: a few EMDs per call on clustered data, amortized.
    virtual std::optional<Neighbor> Next() = 0;
    // stats returns the work done so far by this cursor.
    virtual const SearchStats& stats() const = 0;
  };

  // Creates an empty index. Options are fixed for the index's lifetime.
  // Precondition: ValidateIndexOptions(options) is OK (with invalid
  // build_weights no tree is ever built: searches stay exact, over the
  // buffer).
  explicit SignatureIndex(IndexOptions options);
  // Waits for (and abandons) a running background rebuild.
  ~SignatureIndex();

  SignatureIndex(const SignatureIndex&) = delete;
  SignatureIndex& operator=(const SignatureIndex&) = delete;

  // Upsert inserts `signature` under `id`, replacing any previous one.
  // Returns INVALID_ARGUMENT for an empty id or a malformed signature (see
  // ValidateSignature in ground_distance.h); the index is then unchanged.
  // Cost: one Prepare plus a copy of the buffer (O(rebuild_threshold)).
  absl::Status Upsert(const std::string& id, const Signature& signature);
  // UpsertBatch is Upsert for many entries at once, applied atomically (one
  // snapshot; later entries win over earlier ones with the same id). Use it
  // to load many signatures: per-entry Upsert copies the buffer each time.
  // Returns INVALID_ARGUMENT naming the first bad entry; nothing is applied
  // then. Cost: one Prepare per entry plus O((buffer + m) log(buffer + m)).
  absl::Status UpsertBatch(
      const std::vector<std::pair<std::string, Signature>>& entries);
  // Remove deletes `id`; returns whether it was present.
  bool Remove(const std::string& id);
  // Contains returns whether `id` is present.
  bool Contains(const std::string& id) const;
  // size returns the number of live entries; indexed() those in the tree
  // (live, not tombstoned), buffered() those in the linear buffer.
  size_t size() const;
  size_t indexed() const;
  size_t buffered() const;
  // tombstoned returns the tree entries removed or replaced since the last
  // rebuild (searches skip them; a rebuild drops them). O(1).
  size_t tombstoned() const;
  // rebuilds returns how many tree rebuilds completed since construction
  // (background or called). O(1); thread-safe.
  uint64_t rebuilds() const {
    return rebuilds_.load(std::memory_order_relaxed);
  }
  // MemoryBytes returns the heap bytes of the current snapshot: prepared
  // signatures, centroid table, VP-tree, ids and id map (an estimate for
  // the containers' node overheads). O(size()); thread-safe.
  size_t MemoryBytes() const;

  // Search starts a ranked search under d_w, w = `weights` (metric.h):
  // neighbours in ascending (d_w, id) order with d_w <= radius (radius <= 0:
  // unlimited) and, when `filter` is set, filter(id) true. Every valid
  // weighting is served by the tree (its per-term bounds, vp_tree.h), and
  // the EMD is computed only when weights.emd > 0 (the cursor's
  // stats().emd_computations is then 0); {1, 0, 0} is the
  // paper's distance, IntentWeights(intent) an intent. filter is called at
  // most once per candidate, from the thread calling Next(), and must stay
  // valid while the cursor lives. `stop`, when set, is polled from the same
  // thread before each step that may compute an EMD; once it returns true
  // the cursor ends (Next() returns nullopt), so a cancelled search stops
  // within one EMD (QuerySpec::stop). Returns INVALID_ARGUMENT for a
  // malformed query, a NaN radius or invalid weights (ValidateTermWeights,
  // the message names the term).
  absl::StatusOr<std::unique_ptr<Cursor>> Search(
      const Signature& query, const TermWeights& weights, double radius,
      std::function<bool(const std::string& id)> filter,
      std::function<bool()> stop = nullptr) const;
  // build_weights returns options.build_weights: the tree's own distance.
  const TermWeights& build_weights() const { return options_.build_weights; }
  // Knn returns the min(k, size()) nearest neighbours under build_weights()
  // in ascending (distance, id) order; empty for k == 0 or a malformed
  // query. `stats`, when set, receives the work done.
  std::vector<Neighbor> Knn(const Signature& query, size_t k,
                            SearchStats* stats = nullptr) const;

  // Rebuild folds the buffer and tombstones into a new tree, built outside
  // the lock from a snapshot; writes made meanwhile are replayed onto it.
  // Searches and writes continue during the build. Cost: O(n log n) EMDs.
  void Rebuild();
  // WaitForRebuild blocks until no background rebuild is running.
  void WaitForRebuild();

  // SerializeTree returns the tree's structure (ids, signature fingerprints,
  // vantage-point distances) as bytes; the buffer and tombstones are not in
  // it (the owner persists signatures separately). O(n log n) bytes.
  std::string SerializeTree() const;
  // Load reopens an index from SerializeTree() bytes without a rebuild.
  // `items` are all live entries: those not in the tree (or whose signature
  // changed since the tree was built) go to the buffer; tree ids missing
  // from `items` are tombstoned. Returns DATA_LOSS for corrupt bytes,
  // INVALID_ARGUMENT for bytes of another format version (an older build's
  // tree: the caller rebuilds it from the signatures) or a malformed
  // signature in `items`, FAILED_PRECONDITION when the tree was built with
  // other ground-distance options or other build_weights. Cost: O(bytes +
  // items), no EMD.
  static absl::StatusOr<std::unique_ptr<SignatureIndex>> Load(
      absl::string_view tree_bytes,
      const std::vector<std::pair<std::string, Signature>>& items,
      IndexOptions options);

  struct Snapshot;    // implementation detail, defined in signature_index.cc
  struct SearchPool;  // likewise

 private:
  std::shared_ptr<const Snapshot> snapshot() const;
  // Installs `next` and starts a background rebuild when due. Requires mu_.
  void InstallLocked(std::shared_ptr<const Snapshot> next);
  void StartBackgroundRebuildLocked();

  const IndexOptions options_;
  // The task arena of intra-query parallelism (null when search_threads is
  // 1), shared with the cursors, which may outlive the index.
  std::shared_ptr<SearchPool> pool_;
  mutable std::mutex mu_;
  std::shared_ptr<const Snapshot> snapshot_;  // guarded by mu_
  // Writes made while a rebuild runs, replayed onto its new tree: (id,
  // prepared signature) for an upsert, (id, nullptr) for a remove.
  struct JournalEntry;
  std::vector<JournalEntry>* journal_ = nullptr;  // guarded by mu_
  std::mutex rebuild_mu_;                         // one rebuild at a time
  std::thread background_;                        // guarded by mu_
  bool background_running_ = false;               // guarded by mu_
  std::condition_variable background_done_;
  std::atomic<bool> cancel_{false};
  std::atomic<uint64_t> rebuilds_{0};
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_SIGNATURE_INDEX_H_
