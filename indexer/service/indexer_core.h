// IndexerCore: the logic of tpr-indexer without the wire. It validates
// requests, keeps the durable store (Storage, RocksDB) and the in-memory EMD
// index (tpr::index::SignatureIndex, a VP-tree, Tam & Lau 2007 section 6.2)
// in step, and starts searches. The gRPC service (indexer_service.h) is a
// thin shell over it. Its rooms:
//   model_table.h     the live id table (List, Stats, "does the id exist")
//   label_map.h       the copy-on-write id -> label map searches use
//   tree_persister.h  saves the VP-tree in the background
//   batch_writer.h    the BatchUpsert stream's group commit
//   search_session.h  one running search
//
//   absl::StatusOr<std::unique_ptr<IndexerCore>> core =
//       IndexerCore::Open(opts);
//   absl::StatusOr<bool> created = (*core)->Upsert(request);
//   auto search = (*core)->StartSearch(search_request, /*cancelled=*/nullptr);
//
// Consistency: every write goes through WriteGroup, which holds the writer
// lock across the synced RocksDB write and the index update, so the index
// never holds a model that is not durable and an acknowledged write is
// visible to every later search. A search sees one consistent state: the
// index snapshot (signatures and tree) and the label map snapshot taken
// together when it starts, so a model relabelled or deleted during a search
// keeps, for that search, the label that went with the signature it is
// ranked by.
#ifndef TPR_INDEXER_SERVICE_INDEXER_CORE_H_
#define TPR_INDEXER_SERVICE_INDEXER_CORE_H_

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "common/mutex.h"
#include "indexer/lib/signature.h"
#include "indexer/lib/signature_index.h"
#include "indexer/service/batch_writer.h"
#include "indexer/service/label_map.h"
#include "indexer/service/model_table.h"
#include "indexer/service/search_session.h"
#include "indexer/service/storage.h"
#include "indexer/service/tree_persister.h"
#include "tpr/v1/indexer.pb.h"

namespace tpr::indexer {

// Limits of the contract (indexer.proto).
inline constexpr size_t kMaxIdBytes = 1024;
inline constexpr size_t kMaxLabelBytes = 256;
inline constexpr size_t kMaxMetadataBytes = 64 << 10;
// Largest media accepted on Upsert (ModelMedia): a 256 x 256 RGBA PNG is
// at most about 260 KiB, a 5,000-triangle PLY about 100 KiB. Both stay
// under gRPC's default 4 MiB message limit together with a signature.
inline constexpr size_t kMaxThumbnailBytes = 1 << 20;
inline constexpr size_t kMaxPreviewBytes = 2 << 20;
// Bounds of the List and Stats answers, chosen so that each stays under
// gRPC's default 4 MiB receive limit whatever is stored. A List page ends
// before its models reach kMaxListPageBytes; one model adds at most an id,
// a label and the metadata (about 66 KiB), so a page is below 2.1 MiB.
// Stats reports at most kMaxStatsLabels labels of at most kMaxLabelBytes:
// below 0.3 MiB.
inline constexpr size_t kMaxListPageBytes = 2 << 20;
inline constexpr size_t kMaxStatsLabels = 1000;

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
  // When non-empty, this indexer is a read-only follower of the primary at
  // this address (follower.h): writes fail with FAILED_PRECONDITION naming
  // it, and ApplyReplicated brings the primary's writes in. Promote ends
  // it. Default empty (a primary).
  std::string follow;
  // Threads that parse and convert the stored signatures at Open (most of
  // the open's CPU); 0 uses one per hardware thread
  // (std::thread::hardware_concurrency, at least 1). Default 0.
  int open_threads = 0;
};

// WriteOutcome: what a write group did with one request.
enum class WriteOutcome {
  kSkipped,   // the id existed and overwrite was false: nothing written
  kCreated,   // a new id was stored
  kReplaced,  // an existing model was replaced
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
  // for corrupt data. Models stored with an older signature version are
  // kept, not indexed (searches then fail, see StartSearch). Cost: a scan of
  // the store, O(models) (no EMD when a tree was persisted).
  static absl::StatusOr<std::unique_ptr<IndexerCore>> Open(CoreOptions options);

  // The destructor calls Close().
  ~IndexerCore();
  IndexerCore(const IndexerCore&) = delete;
  IndexerCore& operator=(const IndexerCore&) = delete;

  // Upsert stores request.model and indexes it; durable on return. Returns
  // whether the id was new. The model's media (Model.media) are stored
  // apart, in the same atomic write; an upsert without media removes the
  // id's earlier ones (they would show another mesh). INVALID_ARGUMENT for
  // an empty or too long id, a malformed signature, a thumbnail that is not
  // a PNG or a preview that is not a PLY; RESOURCE_EXHAUSTED for metadata
  // above 64 KiB, media above kMaxThumbnailBytes / kMaxPreviewBytes or too
  // many features; INVALID_ARGUMENT for a label above kMaxLabelBytes, and
  // for an id or label outside the alphabet (valid UTF-8 without control
  // characters), naming the byte;
  // ALREADY_EXISTS when the id exists and overwrite is false;
  // INTERNAL/UNAVAILABLE for a storage failure. Cost: one fsync + O(size).
  absl::StatusOr<bool> Upsert(const tpr::v1::UpsertRequest& request);

  // CheckModel validates `model` (id, metadata size, signature) and
  // converts its signature into *signature. Errors as for Upsert, with the
  // model's id in the message. Cost: O(model size). Thread-safe.
  absl::Status CheckModel(const tpr::v1::Model& model,
                          tpr::index::Signature* signature) const;

  // CheckBands refuses a signature whose band count (options.bands) differs
  // from the index's: that of the first signature stored or loaded, which
  // `fix` (a write) makes `s`'s when none is known yet. INVALID_ARGUMENT
  // naming options.bands and both counts. O(1); thread-safe.
  absl::Status CheckBands(const tpr::index::Signature& s, bool fix) const;

  // WriteGroup is the one write path of models (Upsert and BatchWriter use
  // it): it stores `requests` (validated by CheckModel, `signatures[i]`
  // converted from requests[i]) in one synced RocksDB write, then indexes
  // them with one SignatureIndex::UpsertBatch and updates the label map and
  // the table. Returns each request's outcome; an existing id without
  // overwrite is skipped. Sets each written model's added_unix_micros (a
  // replacement keeps the first time) and media_stored, and moves its
  // media out of the request into the media family. Moves from
  // `signatures`. Errors:
  // the store's (UNAVAILABLE/INTERNAL/DATA_LOSS; nothing written then).
  // Cost: one fsync + O(group size). Thread-safe (serialized with every
  // other write).
  absl::StatusOr<std::vector<WriteOutcome>> WriteGroup(
      std::vector<tpr::v1::UpsertRequest>& requests,
      std::vector<tpr::index::Signature>& signatures);

  // batch_group returns CoreOptions::batch_group.
  size_t batch_group() const { return options_.batch_group; }

  // Delete removes model `id`, durably. NOT_FOUND when unknown,
  // INVALID_ARGUMENT for an empty id. Cost: one fsync.
  absl::Status Delete(const std::string& id);

  // Get returns model `id` with its signature, without its media
  // (media_stored says whether it has them). NOT_FOUND when unknown,
  // INVALID_ARGUMENT for an empty id. Cost: one RocksDB lookup.
  absl::StatusOr<tpr::v1::Model> Get(const std::string& id) const;

  // GetThumbnail returns model `id`'s thumbnail PNG, GetPreview its preview
  // PLY. NOT_FOUND when the id is unknown, or when the model has no such
  // media (added without them; the message names `tpr add --update`,
  // which makes them); INVALID_ARGUMENT for an empty id. Cost: one
  // RocksDB lookup plus the media's bytes. Thread-safe.
  absl::StatusOr<std::string> GetThumbnail(const std::string& id) const;
  absl::StatusOr<std::string> GetPreview(const std::string& id) const;

  // List returns one page of models in ascending id order, signatures
  // omitted. A page size of 0 means 100; above 1000 means 1000. A page ends
  // early, with a next page token, before its models reach
  // kMaxListPageBytes. INVALID_ARGUMENT for a negative page size.
  // Cost: O(log n + page) in memory plus one lookup per model returned;
  // with a label filter, O(models skipped) more.
  absl::StatusOr<tpr::v1::ListResponse> List(
      const tpr::v1::ListRequest& request) const;

  // Stats returns counts and the data directory's size; the per-label
  // counts of the kMaxStatsLabels most populous labels (ties by label).
  // Cost: O(labels) plus a directory listing.
  tpr::v1::StatsResponse Stats() const;

  // StartSearch validates `request` and starts a ranked search over the
  // index snapshot of this moment. `cancelled`, when set, is polled while
  // the search runs (it must stay valid while the session lives); once it
  // returns true the session stops doing EMDs and Next() returns nullopt.
  // INVALID_ARGUMENT for k < 1, a negative or non-finite radius, no query, a
  // malformed signature; RESOURCE_EXHAUSTED for k above options.max_k;
  // NOT_FOUND for an unknown query id; FAILED_PRECONDITION while the store
  // holds models whose signature version is older than the indexer's (the
  // message says to re-extract them with `tpr add --update`), or for a
  // query signature of another version. The search ranks by request.ranking
  // or request.intent (ToTermWeights: INVALID_ARGUMENT naming `ranking` or
  // `intent`), always with the VP-tree. Cost: O(1) to start; see Next.
  absl::StatusOr<std::unique_ptr<SearchSession>> StartSearch(
      const tpr::v1::SearchRequest& request,
      std::function<bool()> cancelled) const;

  // PersistTree saves the index's current VP-tree to the store when it
  // changed since the last save (TreePersister::PersistNow). Cost: O(n log n)
  // bytes serialized + one fsync. Thread-safe.
  absl::Status PersistTree() { return persister_->PersistNow(); }

  // Close stops the background persister and persists the tree once more.
  // Idempotent. For shutdown, after the server stopped: other calls made
  // after Close still work but their tree changes are not persisted.
  void Close();

  // WriteReadiness returns "" while writes are accepted, else the reason
  // (the disk is full: Storage::WriteState, which also retries recovery).
  // For the readiness check (ServerOptions::readiness_check): the service
  // reports NOT_SERVING while writes would fail; reads keep working.
  // Cost: O(1), or one recovery attempt a second. Thread-safe.
  std::string WriteReadiness() {
    absl::Status s = storage_->WriteState();
    return s.ok() ? std::string() : std::string(s.message());
  }

  // WaitForRebuild blocks until no background index rebuild runs (tests and
  // benchmarks use it for a settled tree).
  void WaitForRebuild() { index_->WaitForRebuild(); }

  // ApplyReplicated applies one batch of the primary's write-ahead log
  // (`data` from replication.h LogCursor::Read, first key at `sequence`) to the
  // store (atomically with the new applied sequence, synced) and then to
  // the index, label map and table, as WriteGroup does for local writes.
  // Returns the new applied sequence. FAILED_PRECONDITION when this
  // indexer is not a follower (promoted meanwhile); the errors of
  // ApplyLoggedBatch. Cost: one fsync + O(batch). Thread-safe (serialized
  // with every other write). Defined in indexer_core_replica.cc.
  absl::StatusOr<uint64_t> ApplyReplicated(const std::string& data,
                                           uint64_t sequence);

  // Promote makes a follower a primary: writes are accepted from then on
  // and the store's applied-sequence record is removed. Returns the former
  // primary's address ("" when already a primary: idempotent). Cost: one
  // fsync. Thread-safe. Defined in indexer_core_replica.cc.
  absl::StatusOr<std::string> Promote();

  // following returns the primary's address while this is a follower, ""
  // for a primary. Thread-safe.
  std::string following() const;

  // storage returns the durable store (backups, checkpoints and the
  // write-ahead log read it: replication.h). Thread-safe as Storage is.
  Storage& storage() const { return *storage_; }

  // index returns the in-memory index (for tests and benchmarks).
  const tpr::index::SignatureIndex& index() const { return *index_; }

  // bands returns the band count of the index's signatures (CheckBands), 0
  // while none is known. Thread-safe.
  int bands() const { return bands_.load(); }

  // engine_stats returns the store's RocksDB counters and sizes (metrics;
  // Storage::engine_stats). Thread-safe.
  EngineStats engine_stats() const { return storage_->engine_stats(); }

 private:
  IndexerCore(CoreOptions options, std::unique_ptr<Storage> storage);
  void Log(const std::string& message) const;
  absl::Status LoadIndex();
  // The stored media of `id`, or NOT_FOUND naming `what` is missing.
  absl::StatusOr<tpr::v1::ModelMedia> MediaOf(const std::string& id,
                                              const char* what) const;
  absl::StatusOr<std::vector<WriteOutcome>> WriteGroupLocked(
      std::vector<tpr::v1::UpsertRequest>& requests,
      std::vector<tpr::index::Signature>& signatures)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(write_mu_);

  const CoreOptions options_;
  std::unique_ptr<Storage> storage_;
  std::unique_ptr<tpr::index::SignatureIndex> index_;
  ModelTable table_;
  std::unique_ptr<TreePersister> persister_;
  // See CheckBands; 0 while no signature is known.
  mutable std::atomic<int> bands_{0};

  // Serializes writes: storage write, then index, label map and table
  // updates. Order: write_mu_, then view_mu_.
  tpr::common::Mutex write_mu_;
  // The primary's address while a follower (CoreOptions::follow), else "".
  mutable tpr::common::Mutex follow_mu_;
  std::string follow_ ABSL_GUARDED_BY(follow_mu_);
  // The refusal of a write while following, or OK.
  absl::Status CheckWritable() const;
  // Pairs index updates with label map updates: writers hold it across
  // both, a search start across taking both snapshots.
  mutable tpr::common::Mutex view_mu_;
  LabelMap labels_ ABSL_GUARDED_BY(view_mu_);
  // Stored models whose signature is of an older version (convert.h,
  // kSignatureVersion): kept in the store and the table (Get, List, Delete
  // and overwriting them work), absent from the index; while any is left,
  // searches fail with FAILED_PRECONDITION naming `tpr add --update`.
  std::set<std::string> outdated_ ABSL_GUARDED_BY(view_mu_);
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_INDEXER_CORE_H_
