// IndexerCore: the logic of tpr-indexer without the wire. It validates
// requests, converts tpr.v1 messages to the library's tpr::index::Signature,
// and keeps the durable store (Storage, RocksDB) and the in-memory EMD index
// (tpr::index::SignatureIndex, a VP-tree, Tam & Lau 2007 section 6.2) in
// step. The gRPC service (indexer_service.h) is a thin shell over it.
//
//   absl::StatusOr<std::unique_ptr<IndexerCore>> core = IndexerCore::Open(opts);
//   absl::StatusOr<bool> created = (*core)->Upsert(request);
//   auto search = (*core)->StartSearch(search_request, /*cancelled=*/nullptr);
//
// Consistency: writes are serialized by one mutex held across the synced
// RocksDB write and the index update, so the index never holds a model that
// is not durable and an acknowledged write is visible to every later search.
// A search sees one consistent state: the index snapshot (signatures and
// tree) and the id -> label map snapshot taken together when it starts, so
// a model relabelled or deleted during a search keeps, for that search, the
// label that went with the signature it is ranked by. The label map is
// copy-on-write in hash shards: a write copies the shards it touches (plus
// a vector of shard pointers), a search start copies one shared pointer.
#ifndef TPR_INDEXER_SERVICE_INDEXER_CORE_H_
#define TPR_INDEXER_SERVICE_INDEXER_CORE_H_

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "indexer/lib/signature.h"
#include "indexer/lib/signature_index.h"
#include "indexer/service/storage.h"
#include "tpr/v1/indexer.pb.h"

namespace tpr::indexer {

// Limits of the contract (indexer.proto).
inline constexpr size_t kMaxIdBytes = 1024;
inline constexpr size_t kMaxMetadataBytes = 64 << 10;

// CoreOptions: how IndexerCore opens its data and serves requests.
struct CoreOptions {
  // Directory of the RocksDB database (created when missing). Required.
  std::string data_dir;
  // Storage options (sync writes on by default).
  StorageOptions storage;
  // Index options (ground distance of Eq. 7, rebuild threshold, tree shape).
  // Default: tpr::index::IndexOptions{}.
  tpr::index::IndexOptions index;
  // Largest k a search may ask for; above it RESOURCE_EXHAUSTED. Default
  // 10000.
  int max_k = 10000;
  // Models per synced RocksDB write in a batch upsert (group commit): one
  // fsync per group instead of per model. Default 256.
  size_t batch_group = 256;
  // How often the background persister checks whether the VP-tree changed
  // and saves it, in milliseconds; 0 disables the thread (the tree is then
  // persisted only by PersistTree and at Close). Default 10000.
  int persist_interval_ms = 10000;
  // Receives one line per notable event (open, tree persisted, errors of
  // the background persister). Default: none (silent).
  std::function<void(const std::string&)> log;
};

// ToIndexSignature converts a wire signature to the library's form and
// validates it (tpr::index::ValidateSignature). Returns INVALID_ARGUMENT
// naming the feature at fault (unspecified kind, weights not summing to 1,
// unequal band lengths, non-finite values); RESOURCE_EXHAUSTED above
// tpr::index::kMaxFeatures features. O(size); thread-safe.
absl::StatusOr<tpr::index::Signature> ToIndexSignature(const tpr::v1::Signature& s);

// SearchSession: one running ranked search. Not thread-safe: one caller.
class SearchSession {
 public:
  virtual ~SearchSession() = default;
  // Next returns the next neighbour (rank, id, label, distance) in ascending
  // distance, or nullopt when k were returned, none is left, or the search
  // was cancelled. Cost: a few EMDs per call, amortized.
  virtual std::optional<tpr::v1::Neighbor> Next() = 0;
  // Stats returns the work done so far and the elapsed time.
  virtual tpr::v1::SearchStats Stats() const = 0;
};

// IndexerCore: see the file comment. Thread-safe: every method may be called
// from any number of threads.
class IndexerCore {
 public:
  // Open opens (or creates) the store in options.data_dir and rebuilds the
  // in-memory index from it: the persisted VP-tree is loaded with
  // SignatureIndex::Load (models written after the last persist go to the
  // index's buffer), so no tree build is needed. When no tree was persisted
  // or it cannot be used, the index is built from the models instead.
  // Returns INVALID_ARGUMENT for an empty data_dir, UNAVAILABLE when the
  // database cannot be opened (e.g. locked by another process), DATA_LOSS
  // for corrupt data. Cost: a scan of the store, O(models) (no EMD when a
  // tree was persisted).
  static absl::StatusOr<std::unique_ptr<IndexerCore>> Open(CoreOptions options);

  // The destructor calls Close().
  ~IndexerCore();
  IndexerCore(const IndexerCore&) = delete;
  IndexerCore& operator=(const IndexerCore&) = delete;

  // Upsert stores request.model and indexes it; durable on return. Returns
  // whether the id was new. INVALID_ARGUMENT for an empty or too long id or a
  // malformed signature; RESOURCE_EXHAUSTED for metadata above 64 KiB or too
  // many features; ALREADY_EXISTS when the id exists and overwrite is false;
  // INTERNAL/UNAVAILABLE for a storage failure. Cost: one fsync + O(size).
  absl::StatusOr<bool> Upsert(const tpr::v1::UpsertRequest& request);

  // BatchWriter groups a stream of upserts into synced writes of
  // options.batch_group models (one fsync per group). Add() validates the
  // request and queues it; a full group is handed to a writer thread, so the
  // next group is received and validated while the previous one is synced
  // (at most one group in flight). Finish() writes the rest and waits: every
  // model counted in its answer is durable and indexed when it returns OK.
  // On an error, everything queued before the failing request is written
  // first (so models before it are kept), then the error is returned; a
  // failed group write is reported by the next Add() or Finish(), and no
  // later group is written. Not thread-safe itself (one stream); many
  // BatchWriters may run at once. The destructor waits for the group in
  // flight.
  class BatchWriter {
   public:
    explicit BatchWriter(IndexerCore* core) : core_(core) {}
    ~BatchWriter();
    BatchWriter(const BatchWriter&) = delete;
    BatchWriter& operator=(const BatchWriter&) = delete;
    // Add queues one request. Errors as for Upsert, except that an existing
    // id without overwrite is skipped (counted), not an error.
    absl::Status Add(tpr::v1::UpsertRequest request);
    // Finish writes what is queued and returns the counts.
    absl::StatusOr<tpr::v1::BatchUpsertResponse> Finish();

   private:
    // Starts writing the queued group on the writer thread (after the group
    // in flight is done); returns that earlier group's error.
    absl::Status FlushAsync();
    // Waits for the group in flight; returns its error.
    absl::Status Wait();
    IndexerCore* core_;
    std::thread inflight_;
    absl::Status inflight_status_;  // written by inflight_, read after join
    std::vector<tpr::v1::UpsertRequest> pending_;
    std::vector<tpr::index::Signature> signatures_;
    tpr::v1::BatchUpsertResponse counts_;
  };

  // Delete removes model `id`, durably. NOT_FOUND when unknown,
  // INVALID_ARGUMENT for an empty id. Cost: one fsync.
  absl::Status Delete(const std::string& id);

  // Get returns model `id` with its signature. NOT_FOUND when unknown,
  // INVALID_ARGUMENT for an empty id. Cost: one RocksDB lookup.
  absl::StatusOr<tpr::v1::Model> Get(const std::string& id) const;

  // List returns one page of models in ascending id order, signatures
  // omitted. A page size of 0 means 100; above 1000 means 1000.
  // INVALID_ARGUMENT for a negative page size.
  // Cost: O(log n + page) in memory plus one lookup per model returned;
  // with a label filter, O(models skipped) more.
  absl::StatusOr<tpr::v1::ListResponse> List(const tpr::v1::ListRequest& request) const;

  // Stats returns counts and the data directory's size. Cost: O(labels) plus
  // a directory listing.
  tpr::v1::StatsResponse Stats() const;

  // StartSearch validates `request` and starts a ranked search over the
  // index snapshot of this moment. `cancelled`, when set, is polled while
  // the search runs (it must stay valid while the session lives); once it
  // returns true the session stops doing EMDs and Next() returns nullopt.
  // INVALID_ARGUMENT for k < 1, a negative or non-finite radius, no query, a
  // malformed signature; RESOURCE_EXHAUSTED for k above options.max_k;
  // NOT_FOUND for an unknown query id. Cost: O(1) to start; see Next.
  absl::StatusOr<std::unique_ptr<SearchSession>> StartSearch(
      const tpr::v1::SearchRequest& request, std::function<bool()> cancelled) const;

  // PersistTree saves the index's current VP-tree to the store when it
  // changed since the last save. Cost: O(n log n) bytes serialized + one
  // fsync. Thread-safe.
  absl::Status PersistTree();

  // Close stops the background persister and persists the tree once more.
  // Idempotent. For shutdown, after the server stopped: other calls made
  // after Close still work but their tree changes are not persisted.
  void Close();

  // WaitForRebuild blocks until no background index rebuild runs (tests and
  // benchmarks use it for a settled tree).
  void WaitForRebuild() { index_->WaitForRebuild(); }

  // index returns the in-memory index (for tests and benchmarks).
  const tpr::index::SignatureIndex& index() const { return *index_; }

 private:
  struct Info {
    std::string label;
    int64_t added_unix_micros = 0;
  };

  // Outcome of one request of a write group.
  static constexpr int kSkipped = 0;
  static constexpr int kCreated = 1;
  static constexpr int kReplaced = 2;

  IndexerCore(CoreOptions options, std::unique_ptr<Storage> storage);
  void Log(const std::string& message) const;
  absl::Status LoadIndex();
  // Validates `request` and converts its signature; fills added time later.
  absl::Status CheckModel(const tpr::v1::Model& model,
                          tpr::index::Signature* signature) const;
  // Writes `requests` (validated, with converted signatures) durably and
  // indexes them with one SignatureIndex::UpsertBatch. Requires write_mu_.
  // Counts created/replaced/skipped. Moves from `signatures`.
  absl::Status WriteGroupLocked(std::vector<tpr::v1::UpsertRequest>& requests,
                                std::vector<tpr::index::Signature>& signatures,
                                std::vector<int>* outcome);
  // Publishes a new label map with `changes` applied (label set, or nullopt:
  // removed). Requires view_mu_.
  void ApplyLabelsLocked(
      const std::vector<std::pair<std::string, std::optional<std::string>>>& changes);
  void PersisterLoop();

  const CoreOptions options_;
  std::unique_ptr<Storage> storage_;
  std::unique_ptr<tpr::index::SignatureIndex> index_;

  // Serializes writes: storage write + index update + table update.
  std::mutex write_mu_;
  // The id -> label map searches use: kLabelShards shards by id hash, each
  // immutable once published (copy-on-write).
  static constexpr size_t kLabelShards = 4096;
  using LabelShard = std::unordered_map<std::string, std::string>;
  using LabelMap = std::vector<std::shared_ptr<const LabelShard>>;
  static size_t LabelShardOf(const std::string& id) {
    return std::hash<std::string>()(id) % kLabelShards;
  }
  static const std::string* FindLabel(const LabelMap& labels, const std::string& id);
  // Pairs index updates with label map updates: writers hold it across
  // both, a search start across taking both snapshots. Order: write_mu_,
  // then view_mu_, then table_mu_.
  mutable std::mutex view_mu_;
  std::shared_ptr<const LabelMap> labels_;  // guarded by view_mu_
  // The live id table: id -> label and time added, plus label counts.
  mutable absl::Mutex table_mu_;
  std::map<std::string, Info> table_ ABSL_GUARDED_BY(table_mu_);
  std::map<std::string, int64_t> label_counts_ ABSL_GUARDED_BY(table_mu_);

  // Tree persistence: bytes hash of the last saved tree; writes since then.
  std::mutex persist_mu_;
  size_t persisted_hash_ = 0;      // guarded by persist_mu_
  size_t persisted_indexed_ = 0;   // guarded by persist_mu_
  size_t persisted_buffered_ = 0;  // guarded by persist_mu_
  std::atomic<uint64_t> writes_since_persist_{0};
  std::mutex stop_mu_;
  std::condition_variable stop_cv_;
  bool stopping_ = false;  // guarded by stop_mu_
  std::thread persister_;
  bool closed_ = false;    // guarded by stop_mu_
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_INDEXER_CORE_H_
