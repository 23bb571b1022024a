// SignatureIndex: an immutable VP-tree snapshot plus a small copy-on-write
// buffer and tombstone set (Tam & Lau 2007 section 6.2 builds the tree once;
// a service also needs writes). Why this shape:
// - A search copies one shared_ptr under the mutex and then runs lock-free
//   on an immutable snapshot, so it never blocks writers for more than that
//   copy, and a streaming cursor may live for as long as its client reads.
// - A write copies the buffer and tombstones (bounded by rebuild_threshold)
//   into a new snapshot: O(threshold) per write, no reader ever waits.
// - A rebuild takes the live set of one snapshot, builds outside the lock
//   and replays the writes journaled meanwhile, so no write is lost and no
//   answer is ever inexact.
// - Tree items are numbered in id order, so the tree's (distance, item)
//   order is the (distance, id) order; buffer items are numbered after them
//   and ties across the two are settled by comparing ids.
// - A tree's signatures are copied, once its tree is built, into one
//   huge-page-advised arena in the tree's order (signature_arena.h): a
//   bucket's signatures adjacent, no per-item heap object. A rebuild holds
//   the old arena (still searched) and the new one at once, so its peak is
//   about twice the signatures' bytes.
#include "indexer/lib/signature_index.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <thread>
#include <unordered_map>

#include "absl/strings/str_cat.h"
#include "common/status_macros.h"
#include "indexer/lib/byte_codec.h"
#include "indexer/lib/centroid_table.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/internal/search_pool.h"
#include "indexer/lib/metric.h"
#include "indexer/lib/signature_arena.h"

namespace tpr::index {

namespace {

using PreparedPtr = std::shared_ptr<const PreparedSignature>;

// Fingerprint of a prepared signature: its exact coordinates and masses.
// Prepared coordinates already include the ground-distance weights, so a
// signature prepared under other options does not match either.
uint64_t Fingerprint(const PreparedSignature& p) {
  const int32_t shape[3] = {p.size(), p.bands(), p.stride()};
  uint64_t h = Fnv1a(shape, sizeof shape);
  h = Fnv1a(p.weights(), sizeof(double) * static_cast<size_t>(p.size()), h);
  const size_t rows = static_cast<size_t>(p.rows());
  h = Fnv1a(p.coords(), sizeof(float) * rows * static_cast<size_t>(p.size()),
            h);
  h = Fnv1a(p.spectral(),
            sizeof(float) * static_cast<size_t>(p.spectral_size()), h);
  h = Fnv1a(p.heat(), sizeof(float) * static_cast<size_t>(p.heat_size()), h);
  return h;
}

struct BufferEntry {
  std::string id;
  PreparedPtr prepared;
  uint64_t fingerprint = 0;
};

bool IdLess(const BufferEntry& e, const std::string& id) { return e.id < id; }

}  // namespace

absl::Status ValidateIndexOptions(const IndexOptions& options) {
  TPR_RETURN_IF_ERROR(ValidateOptions(options.ground));
  if (absl::Status s = ValidateTermWeights(options.build_weights); !s.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("index build_weights: ", s.message()));
  }
  return absl::OkStatus();
}

// The tree and what it was built over; shared by every snapshot until the
// next rebuild.
struct TreePart {
  VpTree tree;
  std::vector<std::string> ids;  // item order, strictly increasing
  // The items' signatures, laid out in tree order (absent: unavailable).
  SignatureArena signatures;
  std::vector<uint64_t> fingerprints;

  // Prepared returns item i's signature, nullptr when unavailable. O(1).
  const PreparedSignature* Prepared(uint32_t i) const {
    return signatures.get(i);
  }

  // ItemOf returns the item whose id is `id`, or -1: a binary search of the
  // sorted ids (O(log n) comparisons), which costs no memory per model
  // where a hash map of the ids cost about 60 bytes.
  int64_t ItemOf(const std::string& id) const {
    auto it = std::lower_bound(ids.begin(), ids.end(), id);
    if (it == ids.end() || *it != id) return -1;
    return it - ids.begin();
  }
  // The centroids of the signatures (absent where unavailable), read by
  // the search's lower bound.
  CentroidTable centroids;

  // Sets `signatures` (in the tree's order) and `centroids` from item(i),
  // the signature of item i or nullptr, once `tree` is final; item's
  // results must stay valid during the call.
  void Store(const std::function<const PreparedSignature*(uint32_t)>& item) {
    signatures =
        SignatureArena::Build(ids.size(), tree.ItemsInTreeOrder(), item);
    centroids = CentroidTable::Build(
        ids.size(), [this](uint32_t i) { return signatures.get(i); });
  }
};

struct SignatureIndex::Snapshot {
  std::shared_ptr<const TreePart> tree;
  std::vector<BufferEntry> buffer;   // sorted by id
  std::vector<uint32_t> tombstones;  // sorted tree items

  bool Dead(uint32_t item) const {
    return std::binary_search(tombstones.begin(), tombstones.end(), item);
  }
  void Kill(uint32_t item) {
    auto it = std::lower_bound(tombstones.begin(), tombstones.end(), item);
    if (it == tombstones.end() || *it != item) tombstones.insert(it, item);
  }
  // The live tree item for `id`, or -1.
  int64_t LiveTreeItem(const std::string& id) const {
    const int64_t item = tree->ItemOf(id);
    if (item < 0 || Dead(static_cast<uint32_t>(item))) return -1;
    return item;
  }
  bool Upsert(const std::string& id, PreparedPtr prepared,
              uint64_t fingerprint) {
    const int64_t item = LiveTreeItem(id);
    if (item >= 0) Kill(static_cast<uint32_t>(item));
    auto it = std::lower_bound(buffer.begin(), buffer.end(), id, IdLess);
    if (it != buffer.end() && it->id == id) {
      it->prepared = std::move(prepared);
      it->fingerprint = fingerprint;
      return true;
    }
    buffer.insert(it, BufferEntry{id, std::move(prepared), fingerprint});
    return item >= 0;
  }
  bool Remove(const std::string& id) {
    auto it = std::lower_bound(buffer.begin(), buffer.end(), id, IdLess);
    if (it != buffer.end() && it->id == id) {
      buffer.erase(it);
      return true;  // an id is live in the buffer or the tree, never both
    }
    const int64_t item = LiveTreeItem(id);
    if (item < 0) return false;
    Kill(static_cast<uint32_t>(item));
    return true;
  }
  size_t Pending() const { return buffer.size() + tombstones.size(); }
};

struct SignatureIndex::JournalEntry {
  std::string id;
  PreparedPtr prepared;  // null: a remove
  uint64_t fingerprint = 0;
};

namespace {

std::shared_ptr<TreePart> EmptyTree() { return std::make_shared<TreePart>(); }

class IndexCursor : public SignatureIndex::Cursor {
 public:
  IndexCursor(std::shared_ptr<const SignatureIndex::Snapshot> snapshot,
              PreparedSignature query, const TermWeights& weights,
              double radius, std::function<bool(const std::string&)> filter,
              bool relaxed_bound, std::function<bool()> stop,
              std::shared_ptr<SignatureIndex::SearchPool> pool, size_t batch)
      : pool_(std::move(pool)),
        snapshot_(std::move(snapshot)),
        query_(std::move(query)),
        query_centroid_(Centroid(query_)),
        w_(weights),
        filter_(std::move(filter)) {
    const SignatureIndex::Snapshot* s = snapshot_.get();
    const TreePart* t = s->tree.get();
    n_tree_ = static_cast<uint32_t>(t->ids.size());
    QuerySpec spec;
    spec.weights = {w_.emd, w_.spectral, w_.heat};
    // The tree's terms: 0 the EMD, 1 the spectral term, 2 the heat trace
    // (SignatureIndex::Rebuild); only those the weighting uses are computed.
    spec.distance = [this](uint32_t i, double* out) {
      const PreparedSignature* p = Item(i);
      if (p == nullptr) {
        out[0] = out[1] = out[2] = std::numeric_limits<double>::quiet_NaN();
        return;
      }
      if (w_.emd > 0.0) out[0] = Emd(query_, *p);
      if (w_.spectral > 0.0) out[1] = SpectralDistance(query_, *p);
      if (w_.heat > 0.0) out[2] = HeatDistance(query_, *p);
    };
    AddLowerBounds(t, relaxed_bound, &spec);
    // While one item is refined, the next one's data start loading
    // (QuerySpec::prefetch): beyond a few thousand models they are not in
    // cache, and waiting for them was about a quarter of a 10-NN query's
    // CPU time (docs/search-cost.md). An item still at level 0 needs its
    // centroid row; its signature (3.5 KB at 14 features) only if it
    // passes level 1, so it is prefetched then only while most items so far
    // did (PrefetchSignatureEarly).
    spec.prefetch = [this, t](uint32_t i, size_t level) {
      if (i >= n_tree_) return;
      if (level == 0) {
        t->centroids.Prefetch(i);
        if (w_.heat > 0.0) t->centroids.PrefetchHeat(i);
        if (!PrefetchSignatureEarly(level1_.load(std::memory_order_relaxed),
                                    level2_.load(std::memory_order_relaxed))) {
          return;
        }
      }
      // Through the PreparedSignature object: the block's address kept in
      // a flat array of the centroid table (8 B per model), together with
      // the vantage points' prefetch, measured slower at 1M
      // (docs/search-cost.md), and was dropped.
      if (const PreparedSignature* p = t->Prepared(i)) {
        PrefetchSignature(*p);
      }
    };
    spec.accept = [this, s, t](uint32_t i) {
      if (i < n_tree_ && (t->Prepared(i) == nullptr || s->Dead(i)))
        return false;
      return !filter_ || filter_(Id(i));
    };
    spec.tie_less = [this](uint32_t a, uint32_t b) { return Id(a) < Id(b); };
    for (size_t j = 0; j < s->buffer.size(); ++j) {
      spec.extra_items.push_back(n_tree_ + static_cast<uint32_t>(j));
    }
    if (radius > 0.0) spec.radius = radius;
    spec.stop = std::move(stop);
    if (pool_ != nullptr) {
      spec.parallel_batch = batch;
      SignatureIndex::SearchPool* pool = pool_.get();
      spec.parallel_for = [pool](size_t n,
                                 const std::function<void(size_t)>& body) {
        pool->ParallelFor(n, body);
      };
    }
    inner_ = t->tree.Search(std::move(spec));
  }

  std::optional<Neighbor> Next() override {
    std::optional<ItemNeighbor> next = inner_->Next();
    if (!next) return std::nullopt;
    return Neighbor{Id(next->item), next->distance};
  }
  // The tree counts every distance it computes; without the EMD term (w.emd
  // 0) none of them is an EMD.
  const SearchStats& stats() const override {
    if (w_.emd > 0.0) return inner_->stats();
    stats_ = inner_->stats();
    stats_.emd_computations = 0;
    return stats_;
  }

 private:
  const PreparedSignature* Item(uint32_t i) const {
    if (i < n_tree_) return snapshot_->tree->Prepared(i);
    return snapshot_->buffer[i - n_tree_].prepared.get();
  }

  // The weighted spectral and heat-trace terms of item p, exact (O(n)).
  double Embeddings(const PreparedSignature& p) const {
    double sum = 0.0;
    if (w_.spectral > 0.0) sum += w_.spectral * SpectralDistance(query_, p);
    if (w_.heat > 0.0) sum += w_.heat * HeatDistance(query_, p);
    return sum;
  }

  // Appends the cascade of lower bounds on d_w (emd.h, metric.h), cheapest
  // first. Level 1: the centroid bound (O(bands)) plus lower bounds of the
  // spectral and heat-trace terms, all from the table's rows
  // (CentroidTable: SpectralLowerBound, HeatLowerBound), so that level 1
  // reads no signature. Level 2, only when the EMD is weighed: the relaxed
  // transport bound with capacities on a float32 ground matrix
  // (ConstrainedTransportBound32: half the arithmetic of the double one;
  // the few items that go on to the EMD pay a double matrix of their own)
  // plus the exact embedding terms. Each term enters with its weight, and
  // a term of weight 0 is not computed.
  void AddLowerBounds(const TreePart* t, bool relaxed_bound, QuerySpec* spec) {
    const bool table_spectral =
        t->centroids.spectral_size() == query_.spectral_size();
    const bool table_heat = t->centroids.heat_size() == query_.heat_size();
    spec->lower_bounds.push_back([this, t, table_spectral,
                                  table_heat](uint32_t i) {
      level1_.fetch_add(1, std::memory_order_relaxed);
      if (i >= n_tree_) {
        const PreparedSignature& p = *snapshot_->buffer[i - n_tree_].prepared;
        const double emd = w_.emd > 0.0
                               ? w_.emd * EmdLowerBound(query_centroid_.data(),
                                                        query_.bands(), p)
                               : 0.0;
        return emd + Embeddings(p);
      }
      double sum = w_.emd > 0.0
                       ? w_.emd * t->centroids.LowerBound(
                                      query_centroid_.data(), query_.bands(), i)
                       : 0.0;
      // A table without the embeddings (items of mixed sizes, which one
      // index never holds) gives 0 for their terms.
      if (w_.spectral > 0.0 && table_spectral) {
        sum += w_.spectral * t->centroids.SpectralLowerBound(
                                 query_.spectral(), query_.spectral_size(), i);
      }
      if (w_.heat > 0.0 && table_heat) {
        sum += w_.heat * t->centroids.HeatLowerBound(query_.heat(),
                                                     query_.heat_size(), i);
      }
      return sum;
    });
    if (relaxed_bound && w_.emd > 0.0) {
      spec->lower_bounds.push_back([this](uint32_t i) {
        level2_.fetch_add(1, std::memory_order_relaxed);
        const PreparedSignature* p = Item(i);
        return p == nullptr ? 0.0
                            : w_.emd * ConstrainedTransportBound32(query_, *p) +
                                  Embeddings(*p);
      });
    }
  }
  const std::string& Id(uint32_t i) const {
    if (i < n_tree_) return snapshot_->tree->ids[i];
    return snapshot_->buffer[i - n_tree_].id;
  }

  std::shared_ptr<SignatureIndex::SearchPool> pool_;
  std::shared_ptr<const SignatureIndex::Snapshot> snapshot_;
  PreparedSignature query_;
  std::vector<double> query_centroid_;  // Centroid(query_), for the table
  const TermWeights w_;
  mutable SearchStats stats_;  // stats() without the EMD term
  // Level-1 and level-2 bounds computed so far (for the prefetch policy;
  // atomic because a parallel search computes bounds on several threads).
  std::atomic<int64_t> level1_{0};
  std::atomic<int64_t> level2_{0};
  std::function<bool(const std::string&)> filter_;
  uint32_t n_tree_ = 0;
  // Last: its callbacks point into the members above.
  std::unique_ptr<NeighborCursor> inner_;
};

}  // namespace

SignatureIndex::SignatureIndex(IndexOptions options)
    : options_(std::move(options)) {
  if (options_.search_threads > 1) {
    pool_ = std::make_shared<SearchPool>(options_.search_threads);
  }
  auto s = std::make_shared<Snapshot>();
  s->tree = EmptyTree();
  snapshot_ = std::move(s);
}

SignatureIndex::~SignatureIndex() {
  cancel_ = true;
  std::thread background;
  {
    std::lock_guard<std::mutex> lock(mu_);
    background = std::move(background_);
  }
  if (background.joinable()) background.join();
}

std::shared_ptr<const SignatureIndex::Snapshot> SignatureIndex::snapshot()
    const {
  std::lock_guard<std::mutex> lock(mu_);
  return snapshot_;
}

void SignatureIndex::InstallLocked(std::shared_ptr<const Snapshot> next) {
  snapshot_ = std::move(next);
  if (options_.background_rebuild &&
      snapshot_->Pending() > options_.rebuild_threshold &&
      !background_running_ && !cancel_) {
    StartBackgroundRebuildLocked();
  }
}

void SignatureIndex::StartBackgroundRebuildLocked() {
  // A finished thread has cleared background_running_ and only returns.
  if (background_.joinable()) background_.join();
  background_running_ = true;
  background_ = std::thread([this] {
    Rebuild();
    std::lock_guard<std::mutex> lock(mu_);
    background_running_ = false;
    background_done_.notify_all();
  });
}

void SignatureIndex::WaitForRebuild() {
  std::unique_lock<std::mutex> lock(mu_);
  background_done_.wait(lock, [this] { return !background_running_; });
}

absl::Status SignatureIndex::Upsert(const std::string& id,
                                    const Signature& signature) {
  if (id.empty()) return absl::InvalidArgumentError("empty model id");
  absl::StatusOr<PreparedSignature> prepared =
      Prepare(signature, options_.ground);
  if (!prepared.ok()) {
    return absl::Status(
        prepared.status().code(),
        absl::StrCat("signature of '", id, "': ", prepared.status().message()));
  }
  const uint64_t fingerprint = Fingerprint(*prepared);
  auto shared = std::make_shared<const PreparedSignature>(*std::move(prepared));
  std::lock_guard<std::mutex> lock(mu_);
  auto next = std::make_shared<Snapshot>(*snapshot_);
  next->Upsert(id, shared, fingerprint);
  if (journal_ != nullptr) journal_->push_back({id, shared, fingerprint});
  InstallLocked(std::move(next));
  return absl::OkStatus();
}

absl::Status SignatureIndex::UpsertBatch(
    const std::vector<std::pair<std::string, Signature>>& entries) {
  std::vector<JournalEntry> prepared;
  prepared.reserve(entries.size());
  for (const auto& [id, signature] : entries) {
    if (id.empty()) return absl::InvalidArgumentError("empty model id");
    absl::StatusOr<PreparedSignature> p = Prepare(signature, options_.ground);
    if (!p.ok()) {
      return absl::Status(
          p.status().code(),
          absl::StrCat("signature of '", id, "': ", p.status().message()));
    }
    const uint64_t fingerprint = Fingerprint(*p);
    prepared.push_back(
        {id, std::make_shared<const PreparedSignature>(*std::move(p)),
         fingerprint});
  }
  std::lock_guard<std::mutex> lock(mu_);
  auto next = std::make_shared<Snapshot>(*snapshot_);
  // Merge instead of inserting one by one into the sorted buffer (O(b m)).
  std::map<std::string, BufferEntry> merged;
  for (BufferEntry& e : next->buffer) merged.emplace(e.id, std::move(e));
  for (const JournalEntry& e : prepared) {
    const int64_t item = next->LiveTreeItem(e.id);
    if (item >= 0) next->Kill(static_cast<uint32_t>(item));
    merged[e.id] = BufferEntry{e.id, e.prepared, e.fingerprint};
  }
  next->buffer.clear();
  next->buffer.reserve(merged.size());
  for (auto& [id, e] : merged) next->buffer.push_back(std::move(e));
  if (journal_ != nullptr) {
    journal_->insert(journal_->end(), prepared.begin(), prepared.end());
  }
  InstallLocked(std::move(next));
  return absl::OkStatus();
}

bool SignatureIndex::Remove(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto next = std::make_shared<Snapshot>(*snapshot_);
  if (!next->Remove(id)) return false;
  if (journal_ != nullptr) journal_->push_back({id, nullptr, 0});
  InstallLocked(std::move(next));
  return true;
}

bool SignatureIndex::Contains(const std::string& id) const {
  std::shared_ptr<const Snapshot> s = snapshot();
  auto it = std::lower_bound(s->buffer.begin(), s->buffer.end(), id, IdLess);
  if (it != s->buffer.end() && it->id == id) return true;
  return s->LiveTreeItem(id) >= 0;
}

size_t SignatureIndex::size() const {
  std::shared_ptr<const Snapshot> s = snapshot();
  return s->tree->ids.size() - s->tombstones.size() + s->buffer.size();
}

size_t SignatureIndex::indexed() const {
  std::shared_ptr<const Snapshot> s = snapshot();
  return s->tree->ids.size() - s->tombstones.size();
}

size_t SignatureIndex::buffered() const { return snapshot()->buffer.size(); }

size_t SignatureIndex::tombstoned() const {
  return snapshot()->tombstones.size();
}

size_t SignatureIndex::MemoryBytes() const {
  const std::shared_ptr<const Snapshot> s = snapshot();
  const TreePart& t = *s->tree;
  // A shared_ptr'd object with make_shared costs its control block (two
  // counters and a vtable pointer) beside it; a std::string its heap
  // buffer when longer than the small-string capacity.
  constexpr size_t kControlBlock = 3 * sizeof(void*);
  auto string_bytes = [](const std::string& id) {
    return id.capacity() > 15 ? id.capacity() + 1 : 0;
  };
  size_t bytes = t.tree.MemoryBytes() + t.centroids.MemoryBytes() +
                 t.ids.capacity() * sizeof(std::string) +
                 t.signatures.MemoryBytes() +
                 t.fingerprints.capacity() * sizeof(uint64_t);
  for (const std::string& id : t.ids) bytes += string_bytes(id);
  for (const BufferEntry& e : s->buffer) {
    bytes += sizeof(BufferEntry) + string_bytes(e.id);
    if (e.prepared != nullptr) {
      bytes +=
          sizeof(PreparedSignature) + kControlBlock + e.prepared->MemoryBytes();
    }
  }
  return bytes + s->tombstones.capacity() * sizeof(uint32_t);
}

absl::StatusOr<std::unique_ptr<SignatureIndex::Cursor>> SignatureIndex::Search(
    const Signature& query, const TermWeights& weights, double radius,
    std::function<bool(const std::string& id)> filter,
    std::function<bool()> stop) const {
  TPR_RETURN_IF_ERROR(ValidateTermWeights(weights));
  if (std::isnan(radius)) return absl::InvalidArgumentError("radius is NaN");
  absl::StatusOr<PreparedSignature> prepared = Prepare(query, options_.ground);
  if (!prepared.ok()) {
    return absl::Status(
        prepared.status().code(),
        absl::StrCat("query signature: ", prepared.status().message()));
  }
  return std::unique_ptr<Cursor>(std::make_unique<IndexCursor>(
      snapshot(), *std::move(prepared), weights, radius, std::move(filter),
      options_.relaxed_bound, std::move(stop), pool_,
      options_.search_batch > 0
          ? options_.search_batch
          : 2 * static_cast<size_t>(std::max(options_.search_threads, 1))));
}

std::vector<Neighbor> SignatureIndex::Knn(const Signature& query, size_t k,
                                          SearchStats* stats) const {
  std::vector<Neighbor> out;
  if (stats != nullptr) *stats = SearchStats{};
  if (k == 0) return out;
  absl::StatusOr<std::unique_ptr<Cursor>> cursor =
      Search(query, options_.build_weights, 0.0, nullptr);
  if (!cursor.ok()) return out;
  while (out.size() < k) {
    std::optional<Neighbor> next = (*cursor)->Next();
    if (!next) break;
    out.push_back(*std::move(next));
  }
  if (stats != nullptr) *stats = (*cursor)->stats();
  return out;
}

void SignatureIndex::Rebuild() {
  std::lock_guard<std::mutex> rebuild_lock(rebuild_mu_);
  std::vector<JournalEntry> journal;
  std::shared_ptr<const Snapshot> base;
  {
    std::lock_guard<std::mutex> lock(mu_);
    base = snapshot_;
    journal_ = &journal;
  }
  // The live set of `base`, in id order (tree and buffer ids are disjoint;
  // `base` keeps every signature named here alive).
  struct Live {
    const std::string* id;
    const PreparedSignature* prepared;
    uint64_t fingerprint;
  };
  std::vector<Live> live;
  const TreePart& old = *base->tree;
  for (uint32_t i = 0; i < old.ids.size(); ++i) {
    if (old.Prepared(i) != nullptr && !base->Dead(i)) {
      live.push_back({&old.ids[i], old.Prepared(i), old.fingerprints[i]});
    }
  }
  for (const BufferEntry& e : base->buffer) {
    live.push_back({&e.id, e.prepared.get(), e.fingerprint});
  }
  std::sort(live.begin(), live.end(),
            [](const Live& a, const Live& b) { return *a.id < *b.id; });
  auto part = std::make_shared<TreePart>();
  part->ids.reserve(live.size());  // exact capacities: MemoryBytes counts them
  part->fingerprints.reserve(live.size());
  for (const Live& l : live) {
    part->ids.push_back(*l.id);
    part->fingerprints.push_back(l.fingerprint);
  }
  // Every term is stored, whatever the build weights, so that any
  // weighting can be bounded (the terms' order is IndexCursor's).
  const TermWeights& b = options_.build_weights;
  absl::StatusOr<VpTree> tree = VpTree::Build(
      live.size(), 3,
      [&live](uint32_t i, uint32_t j, double* out) {
        const PreparedSignature& x = *live[i].prepared;
        const PreparedSignature& y = *live[j].prepared;
        out[0] = Emd(x, y);
        out[1] = SpectralDistance(x, y);
        out[2] = HeatDistance(x, y);
      },
      {b.emd, b.spectral, b.heat}, options_.tree, &cancel_);
  if (tree.ok()) {
    // Outside mu_, like the tree: the copy into the arena and the centroids.
    part->tree = *std::move(tree);
    part->Store([&live](uint32_t i) { return live[i].prepared; });
  }
  std::lock_guard<std::mutex> lock(mu_);
  journal_ = nullptr;
  // Only cancellation (destruction) or invalid tree options fail here; the
  // current snapshot then stays, still exact.
  if (!tree.ok()) return;
  auto next = std::make_shared<Snapshot>();
  next->tree = std::move(part);
  for (JournalEntry& e : journal) {
    if (e.prepared != nullptr) {
      next->Upsert(e.id, std::move(e.prepared), e.fingerprint);
    } else {
      next->Remove(e.id);
    }
  }
  snapshot_ = std::move(next);
  rebuilds_.fetch_add(1, std::memory_order_relaxed);
}

// ---------------------------------------------------------------------------
// Persistence. Layout (little-endian), FNV-1a 64 checksum last:
//   "TPRSIX" u16 version | f64 w1 w2 w3 w4 k_scale a_scale h_scale
//   u32 n | n x (u32 id length, id bytes, u64 fingerprint)
//   u64 tree length, VpTree::Serialize() bytes | u64 checksum

namespace {

constexpr Frame kFrame{"TPRSIX", /*version=*/2, "signature-index",
                       "corrupt index bytes"};

std::vector<double> OptionValues(const GroundDistanceOptions& g) {
  return {g.w1, g.w2, g.w3, g.w4, g.k_scale, g.a_scale, g.h_scale};
}

absl::Status Corrupt(absl::string_view what) {
  return CorruptFrame(kFrame, what);
}

}  // namespace

std::string SignatureIndex::SerializeTree() const {
  std::shared_ptr<const Snapshot> s = snapshot();
  const TreePart& t = *s->tree;
  std::string out = BeginFrame(kFrame);
  for (double v : OptionValues(options_.ground)) {
    uint64_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    PutU(&out, bits, 8);
  }
  PutU(&out, t.ids.size(), 4);
  for (size_t i = 0; i < t.ids.size(); ++i) {
    PutU(&out, t.ids[i].size(), 4);
    out += t.ids[i];
    PutU(&out, t.fingerprints[i], 8);
  }
  const std::string tree = t.tree.Serialize();
  PutU(&out, tree.size(), 8);
  out += tree;
  EndFrame(&out);
  return out;
}

absl::StatusOr<std::unique_ptr<SignatureIndex>> SignatureIndex::Load(
    absl::string_view tree_bytes,
    const std::vector<std::pair<std::string, Signature>>& items,
    IndexOptions options) {
  TPR_RETURN_IF_ERROR(ValidateIndexOptions(options));
  TPR_ASSIGN_OR_RETURN(const absl::string_view payload,
                       OpenFrame(tree_bytes, kFrame));
  ByteReader r(payload);
  const std::vector<double> want = OptionValues(options.ground);
  for (double w : want) {
    uint64_t bits;
    if (!r.U(8, &bits)) return Corrupt("truncated options");
    double v;
    std::memcpy(&v, &bits, sizeof v);
    if (!(v == w)) {
      return absl::FailedPreconditionError(
          "the tree was built with other ground-distance options; rebuild it");
    }
  }
  uint64_t n;
  if (!r.U(4, &n) || n * 12 > r.remaining()) return Corrupt("item count");
  auto part = std::make_shared<TreePart>();
  part->ids.resize(n);
  part->fingerprints.resize(n);
  // The tree's signatures until they move into its arena.
  std::vector<PreparedSignature> tree_items(n);
  for (uint64_t i = 0; i < n; ++i) {
    uint64_t len;
    absl::string_view id;
    if (!r.U(4, &len) || !r.Bytes(len, &id) ||
        !r.U(8, &part->fingerprints[i])) {
      return Corrupt("truncated id table");
    }
    part->ids[i] = std::string(id);
    if (id.empty() || (i > 0 && !(part->ids[i - 1] < part->ids[i]))) {
      return Corrupt("ids not strictly increasing");
    }
  }
  uint64_t tree_len;
  absl::string_view tree_part;
  if (!r.U(8, &tree_len) || tree_len != r.remaining() ||
      !r.Bytes(tree_len, &tree_part)) {
    return Corrupt("tree length");
  }
  TPR_ASSIGN_OR_RETURN(part->tree, VpTree::Deserialize(tree_part));
  if (part->tree.size() != n) return Corrupt("tree size differs from id table");
  const TermWeights& b = options.build_weights;
  if (n > 0 &&
      (part->tree.terms() != 3 ||
       part->tree.build_weights() != TermVector{b.emd, b.spectral, b.heat})) {
    return absl::FailedPreconditionError(
        "the tree was built with other build weights; rebuild it");
  }

  auto index = std::make_unique<SignatureIndex>(std::move(options));
  auto snap = std::make_shared<Snapshot>();
  std::vector<bool> seen(n, false);
  std::unordered_map<std::string, bool> given;
  for (const auto& [id, signature] : items) {
    if (id.empty())
      return absl::InvalidArgumentError("empty model id in items");
    if (!given.emplace(id, true).second) {
      return absl::InvalidArgumentError(
          absl::StrCat("duplicate id '", id, "' in items"));
    }
    absl::StatusOr<PreparedSignature> prepared =
        Prepare(signature, index->options_.ground);
    if (!prepared.ok()) {
      return absl::Status(prepared.status().code(),
                          absl::StrCat("signature of '", id,
                                       "': ", prepared.status().message()));
    }
    const uint64_t fingerprint = Fingerprint(*prepared);
    const int64_t item = part->ItemOf(id);
    if (item >= 0 &&
        part->fingerprints[static_cast<size_t>(item)] == fingerprint) {
      tree_items[static_cast<size_t>(item)] = *std::move(prepared);
      seen[static_cast<size_t>(item)] = true;
    } else {
      // New, or changed since the tree was built: the stored distances do
      // not describe it, so it is searched linearly until the next rebuild.
      snap->buffer.push_back(
          {id, std::make_shared<const PreparedSignature>(*std::move(prepared)),
           fingerprint});
    }
  }
  std::sort(
      snap->buffer.begin(), snap->buffer.end(),
      [](const BufferEntry& a, const BufferEntry& b) { return a.id < b.id; });
  for (uint32_t i = 0; i < n; ++i) {
    if (!seen[i]) snap->tombstones.push_back(i);
  }
  part->Store([&](uint32_t i) { return seen[i] ? &tree_items[i] : nullptr; });
  std::vector<PreparedSignature>().swap(tree_items);
  snap->tree = std::move(part);
  std::lock_guard<std::mutex> lock(index->mu_);
  index->InstallLocked(std::move(snap));
  return index;
}

}  // namespace tpr::index
