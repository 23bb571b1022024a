// Durable storage of tpr-indexer: the source of truth for the stored models
// and the persisted VP-tree, in RocksDB under the --data-dir. With
// replication.cc (backups, checkpoints, log tailing), the only files that
// include RocksDB.
//
//   absl::StatusOr<std::unique_ptr<Storage>> db = Storage::Open(dir);
//   TPR_RETURN_IF_ERROR((*db)->Write({{"cat/1", &model}}));   // synced
//   absl::StatusOr<tpr::v1::Model> m = (*db)->GetModel("cat/1");
//
// Layout (RocksDB column families):
//   "models"   key = model id (raw bytes, so RocksDB's bytewise order is id
//              order), value = 8-byte little-endian write sequence number
//              followed by the serialized tpr.v1.Model (signature, label,
//              metadata, added_unix_micros).
//   "media"    key = model id, value = the serialized tpr.v1.ModelMedia
//              (thumbnail PNG, preview PLY) of the models that have them:
//              kept apart so that the scan at open and every model read
//              skip their bytes. Written and deleted in the same batch as
//              the model (a put without media deletes them).
//   "default"  key "tree" = the VP-tree bytes of the last persist
//              (SignatureIndex::SerializeTree), key "tree_seq" = 8-byte
//              little-endian write sequence number that tree reflects,
//              key "last_seq" = the last sequence number any write used,
//              key "model_count" = the number of models, key
//              "write_count" = the number of Write batches (8-byte
//              little-endian; all written in the same batch as the models).
// Beside RocksDB's files, ACKNOWLEDGED (ack_file.h) records the write count
// and model count acknowledged to a caller.
// Every model write takes the next sequence number. A model whose sequence
// number is greater than "tree_seq" was written after the tree was
// persisted: on reopen it is certainly not in the tree (IndexerCore logs how
// many). SignatureIndex::Load itself puts every model that is not in the
// tree, or whose signature changed, into its insert buffer, by comparing
// signature fingerprints. Tree and marker are written in one atomic batch.
//
// Durability: every Write uses WriteOptions::sync = true, so an
// acknowledged write survives kill -9 and power loss (RocksDB replays the
// synced write-ahead log on open). Batch upserts are grouped by the caller
// into one Write (one fsync per group, plus one of the small ACKNOWLEDGED).
//
// No silent loss: Open refuses, with DATA_LOSS naming the files, a database
// that holds less than ACKNOWLEDGED says was acknowledged (a truncated
// MANIFEST, a damaged write-ahead log), and checks it read-only first so
// that a refused database loses no file; the caller's scan is checked with
// CheckScanned. The RocksDB recovery settings and why: storage.cc
// (DbOptions). What an operator does then: docs/recovery.md.
#ifndef TPR_INDEXER_SERVICE_STORAGE_H_
#define TPR_INDEXER_SERVICE_STORAGE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tpr/v1/indexer.pb.h"

namespace rocksdb {
class DB;
class ColumnFamilyHandle;
}  // namespace rocksdb

namespace tpr::indexer {

// StorageOptions: how Storage::Open configures RocksDB.
struct StorageOptions {
  // Sync the write-ahead log before every acknowledged write. Turning this
  // off breaks the kill -9 promise; only benchmarks that measure its cost
  // should. Default true.
  bool sync_writes = true;
  // Create the directory and database when missing. Default true.
  bool create_if_missing = true;
  // Observers for metrics: the duration in seconds of each Write (existence
  // lookups, the RocksDB write with its log sync, the ACKNOWLEDGED record;
  // called on the writing thread after a successful write) and of each
  // fsync of RocksDB's write-ahead log (called on the thread RocksDB syncs
  // on). Must be thread-safe and quick. Default none.
  std::function<void(double seconds)> on_write;
  std::function<void(double seconds)> on_wal_sync;
  // How long closed write-ahead log files are kept (archived) so that a
  // follower can tail them (RocksDB WAL_ttl_seconds), in seconds, and at
  // most how many MB of them (WAL_size_limit_MB). A follower further
  // behind than the kept log starts again from a checkpoint. 0 and 0: no
  // archive. Default 3600 s, 1024 MB.
  uint64_t wal_keep_seconds = 3600;
  uint64_t wal_keep_mb = 1024;
};

// EngineStats: RocksDB's own counters (its statistics and an event
// listener) and sizes (its properties), for metrics.
struct EngineStats {
  // Time writes spent delayed or stopped by RocksDB's write controller
  // (ticker STALL_MICROS), in microseconds.
  uint64_t stall_micros = 0;
  // Times a column family entered the delayed or the stopped write
  // condition (too many memtables or level-0 files, pending compaction).
  uint64_t delayed_stalls = 0;
  uint64_t stopped_stalls = 0;
  // Syncs of the write-ahead log (ticker WAL_FILE_SYNCED).
  uint64_t wal_syncs = 0;
  // Sum over the column families of the properties
  // rocksdb.estimate-live-data-size, rocksdb.total-sst-files-size and
  // rocksdb.cur-size-all-mem-tables.
  uint64_t live_data_bytes = 0;
  uint64_t sst_bytes = 0;
  uint64_t memtable_bytes = 0;
};

// RocksHandles: the open database, for replication.cc (backups,
// checkpoints, the write-ahead log). Owned by the Storage.
struct RocksHandles {
  rocksdb::DB* db = nullptr;
  rocksdb::ColumnFamilyHandle* meta = nullptr;    // "default"
  rocksdb::ColumnFamilyHandle* models = nullptr;  // "models"
  rocksdb::ColumnFamilyHandle* media = nullptr;   // "media"
};

// PersistedTree: the VP-tree bytes of the last persist and the write
// sequence number they reflect.
struct PersistedTree {
  std::string bytes;
  uint64_t seq = 0;
};

// ModelWrite: one mutation of a Storage::Write batch: a put when `model` is
// non-null, else a delete of `id` and its media. A put stores `media` in
// the media family when it is non-null and holds bytes, and deletes the
// id's earlier media otherwise. `model` itself should carry no media (its
// `media` field is stored as given, in the models family).
struct ModelWrite {
  std::string id;
  const tpr::v1::Model* model = nullptr;
  const tpr::v1::ModelMedia* media = nullptr;
};

// Storage: RocksDB-backed model store. Thread-safe (RocksDB is); the caller
// orders writes against its in-memory index (IndexerCore holds its writer
// lock across a Write and the index update).
class Storage {
 public:
  // Open opens or creates the database in `dir`. Returns INVALID_ARGUMENT for
  // an empty dir, UNAVAILABLE when RocksDB cannot open it (locked by another
  // process, unreadable), DATA_LOSS when it is corrupt or holds less than
  // was acknowledged (the message names the MANIFEST and write-ahead logs;
  // nothing is deleted then). Cost: RocksDB recovery (WAL replay) twice, a
  // read-only check and the open, typically milliseconds to a second; a
  // database written before the model count existed is counted once
  // (a key scan).
  static absl::StatusOr<std::unique_ptr<Storage>> Open(
      const std::string& dir, const StorageOptions& options = {});

  // The destructor flushes RocksDB's memtables (so the next Open has no
  // write-ahead log to replay; up to 64 MB, a fraction of a second) and
  // closes the database.
  ~Storage();
  Storage(const Storage&) = delete;
  Storage& operator=(const Storage&) = delete;

  // Write applies `writes` atomically in one RocksDB batch (synced when
  // options.sync_writes), assigns each put the next sequence number, counts
  // the batch and keeps the model count (a delete of an absent id changes
  // nothing), then records both counts in ACKNOWLEDGED. Returns
  // UNAVAILABLE/INTERNAL on an I/O error (then nothing was written, unless only
  // the ACKNOWLEDGED record failed); RESOURCE_EXHAUSTED when the disk is full
  // (see WriteState). Cost: one point lookup per id (Bloom-filtered), one fsync
  // of the log and one of ACKNOWLEDGED, plus O(total bytes). Thread-safe.
  absl::Status Write(const std::vector<ModelWrite>& writes);

  // GetModel returns the stored model `id`; NOT_FOUND when absent, DATA_LOSS
  // when its bytes do not parse. Cost: one point lookup. Thread-safe.
  absl::StatusOr<tpr::v1::Model> GetModel(const std::string& id) const;

  // GetMedia returns the media stored for model `id`; NOT_FOUND when it
  // has none (whether or not the model exists), DATA_LOSS when the bytes
  // do not parse. Cost: one point lookup plus the media's bytes.
  // Thread-safe.
  absl::StatusOr<tpr::v1::ModelMedia> GetMedia(const std::string& id) const;

  // ForEachModel calls `fn(seq, model)` for every stored model, stopping at
  // the first non-OK status, which it returns (DATA_LOSS for a record that
  // does not parse). With threads <= 1 (default) fn runs on the calling
  // thread in ascending id order. With threads > 1 the records are parsed
  // and fn is called on `threads` worker threads, concurrently and in no
  // particular order (fn must be thread-safe; after an error, calls already
  // under way finish). Used once at open. Cost: a full scan; parsing spread
  // over the threads. Thread-safe (reads a snapshot).
  absl::Status ForEachModel(
      const std::function<absl::Status(uint64_t seq, tpr::v1::Model&& model)>&
          fn,
      int threads = 1) const;

  // SaveTree persists `tree_bytes` with marker `seq`, atomically and synced.
  // `seq` must be a last_seq() value read BEFORE the tree was serialized:
  // then every write after the marker is certainly not reflected in the
  // tree (writes at or below it may still sit in the index's buffer, which
  // SignatureIndex::Load detects by signature fingerprint). Returns
  // INTERNAL/UNAVAILABLE on an I/O error. Cost: one fsync + O(bytes).
  // Thread-safe.
  absl::Status SaveTree(const std::string& tree_bytes, uint64_t seq);

  // LoadTree returns the last persisted tree; NOT_FOUND when none was ever
  // saved. Cost: one lookup. Thread-safe.
  absl::StatusOr<PersistedTree> LoadTree() const;

  // last_seq returns the sequence number of the last model write (0 when
  // none). Thread-safe.
  uint64_t last_seq() const;

  // WriteState returns OK while writes are accepted. After a write failed
  // because the disk is full, writes fail fast with RESOURCE_EXHAUSTED
  // (which clients do not retry); WriteState then tries RocksDB's
  // DB::Resume, at most once a second, and returns OK again once it
  // succeeds, i.e. once space was freed: no restart is needed. Readiness
  // polls it (IndexerCore::WriteReadiness); Write calls it first while
  // writes are refused. Cost: O(1), or one Resume attempt (a flush).
  // Thread-safe.
  absl::Status WriteState();

  // model_count returns the number of stored models. Thread-safe.
  uint64_t model_count() const;

  // CheckScanned returns DATA_LOSS (naming the files) when a full scan
  // found `scanned` models but model_count() were recorded; OK otherwise.
  // IndexerCore calls it after its scan at open. Thread-safe.
  absl::Status CheckScanned(uint64_t scanned) const;

  // rocks returns the open database's handles (valid while the Storage
  // lives) and dir the data directory. Thread-safe.
  RocksHandles rocks() const;
  const std::string& dir() const;

  // ReloadCounters re-reads the sequence counter, the model count and the
  // write count from the database after writes made outside Write (a
  // follower applying its primary's batches, replication.h), and records
  // them in ACKNOWLEDGED. Call under the caller's writer lock. Returns the
  // store's error. Cost: three point lookups and one fsync. Thread-safe.
  absl::Status ReloadCounters();

  // DiskBytes returns the bytes the data directory occupies on disk (sum of
  // its files' sizes). Cost: one directory listing. Thread-safe.
  int64_t DiskBytes() const;

  // engine_stats returns RocksDB's counters and sizes (see EngineStats).
  // Cost: a few property reads. Thread-safe.
  EngineStats engine_stats() const;

 private:
  struct Impl;
  explicit Storage(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_STORAGE_H_
