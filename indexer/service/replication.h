// Copying an indexer's data with RocksDB's own mechanisms: online
// incremental backups (BackupEngine), consistent copies for a starting
// follower (Checkpoint), and the primary's write-ahead log for a follower to
// tail (GetUpdatesSince) and apply. No consensus of our own: one primary per
// shard, followers copy it, promotion is an operator's command.
//
//   absl::StatusOr<BackupResult> b =
//       CreateBackup(storage, "/backups/shard0", 7);
//   absl::StatusOr<RestoreResult> r =
//       RestoreBackup("/backups/shard0", 0, "/data/new");
//   absl::StatusOr<uint64_t> seq =
//       CreateCheckpoint(storage, dir + "/.checkpoint-1");
//   LogCursor cursor(storage, seq + 1);
//   absl::StatusOr<std::vector<LoggedBatch>> log = cursor.Read(4 << 20);
//   absl::StatusOr<AppliedBatch> a =
//       ApplyLoggedBatch(follower_storage, log[0].data,
//                        log[0].sequence);
//
// Everything the persisted VP-tree needs travels with the models: the tree
// and its marker live in the same RocksDB database (storage.h), so a
// backup, a checkpoint and the log carry them consistently.
//
// With storage.cc, the only file that includes RocksDB.
#ifndef TPR_INDEXER_SERVICE_REPLICATION_H_
#define TPR_INDEXER_SERVICE_REPLICATION_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "indexer/service/storage.h"
#include "tpr/v1/indexer.pb.h"

namespace tpr::indexer {

// BackupResult: one new backup of a backup set.
struct BackupResult {
  uint32_t backup_id = 0;
  // Bytes and files the backup references (shared files counted in full).
  uint64_t size_bytes = 0;
  uint32_t files = 0;
  // Bytes the backup set grew by (the files this backup had to copy).
  uint64_t copied_bytes = 0;
  // Seconds since the Unix epoch when it was taken.
  int64_t unix_seconds = 0;
};

// CreateBackup adds a backup of `storage`'s database to the backup set in
// `backup_dir` (created when missing) with RocksDB's BackupEngine: memtables
// are flushed first, table files already in the set are shared, not copied
// again (incremental); then every file of the new backup is re-read and
// checksummed (VerifyBackup). With keep_last > 0 only the keep_last newest
// backups are kept afterwards. Online: writes and searches go on (RocksDB
// pins the files while copying). Returns INVALID_ARGUMENT for an empty
// backup_dir or one inside the data directory, UNAVAILABLE/INTERNAL for I/O
// errors, DATA_LOSS when verification fails. Cost: a flush, a copy of the
// files not yet in the set and a read of the whole backup. Thread-safe
// (concurrent backups into the same set are serialized by a process-wide
// lock; RocksDB forbids concurrent writers of one set).
absl::StatusOr<BackupResult> CreateBackup(Storage& storage,
                                          const std::string& backup_dir,
                                          int keep_last);

// RestoreResult: what RestoreBackup restored.
struct RestoreResult {
  uint32_t backup_id = 0;
};

// RestoreBackup restores backup `backup_id` (0: the latest) of the set in
// `backup_dir` into `data_dir`, which must be absent or an empty directory:
// FAILED_PRECONDITION naming it otherwise (a restore never overwrites
// data). The backup is verified (checksums) before it is restored. The
// restored database gets a new identity (ForgetDatabaseIdentity): followers
// of the original refuse to tail it. Returns
// NOT_FOUND for a missing set or backup id, DATA_LOSS when verification
// fails, UNAVAILABLE/INTERNAL for I/O errors. Cost: a read of the backup and
// a copy of its files. Thread-safe.
absl::StatusOr<RestoreResult> RestoreBackup(const std::string& backup_dir,
                                            uint32_t backup_id,
                                            const std::string& data_dir);

// CreateCheckpoint writes a consistent copy of `storage`'s database into
// `dir` (which must not exist; hard links where the file system allows) and
// returns the RocksDB sequence number it reflects: a follower continues
// from the next one. Cost: a flush and one link or copy per file.
// Thread-safe.
absl::StatusOr<uint64_t> CreateCheckpoint(Storage& storage,
                                          const std::string& dir);

// LatestSequence returns the RocksDB sequence number of the last write
// (RocksDB numbers every key written). Thread-safe, O(1).
uint64_t LatestSequence(const Storage& storage);

// LoggedBatch: one write batch of the write-ahead log.
struct LoggedBatch {
  // Sequence number of its first key; it uses `count` numbers from there.
  uint64_t sequence = 0;
  uint32_t count = 0;
  // WriteBatch::Data(): the batch's bytes, as ApplyLoggedBatch takes them.
  std::string data;
};

// LogCursor reads `storage`'s write-ahead log forward from a sequence
// number, for a follower's TailLog stream. It keeps RocksDB's
// TransactionLogIterator (GetUpdatesSince) open between reads and only asks
// it for what was written since (TransactionLogIterator::Next re-reads the
// end of the current log file), so a caught-up follower costs each poll the
// new bytes only. It opens a new iterator, which reads the log file holding
// the next sequence from that file's start, when the primary has started a
// new log file since, or after an error. (Reopening on every poll cost
// O(log file size) per poll: the follower fell behind at ~1000 models/s;
// bench_gateway BM_FollowerLag.) Not thread-safe: one cursor per stream.
class LogCursor {
 public:
  // The cursor starts at sequence `from`; `storage` must outlive it.
  LogCursor(Storage& storage, uint64_t from);
  ~LogCursor();
  LogCursor(const LogCursor&) = delete;
  LogCursor& operator=(const LogCursor&) = delete;

  // Read returns the next batches of the log, in order and contiguous, the
  // first holding next() (it may start before it), until their bytes reach
  // max_bytes (at least one batch when any is there), and moves next() past
  // them; empty when nothing was written at or after next(). Returns
  // OUT_OF_RANGE when next() is no longer in the kept log (archived logs are
  // kept for StorageOptions::wal_keep_seconds / wal_keep_mb), naming both
  // numbers; UNAVAILABLE/INTERNAL for read errors. Cost: the bytes read;
  // after a new log file was started or an error, also the log file from
  // its start to next().
  absl::StatusOr<std::vector<LoggedBatch>> Read(size_t max_bytes);

  // The first sequence number Read has not returned yet.
  uint64_t next() const { return next_; }

 private:
  struct Iterator;
  Storage& storage_;
  uint64_t next_;
  std::unique_ptr<Iterator> it_;
};

// ReplicatedChange: one model a replicated batch put or deleted.
struct ReplicatedChange {
  std::string id;
  // The model put, with its write sequence number; empty for a delete.
  std::optional<tpr::v1::Model> model;
};

// AppliedBatch: what ApplyLoggedBatch did.
struct AppliedBatch {
  // The primary sequence number of the batch's last key: the follower's
  // new applied sequence.
  uint64_t last_sequence = 0;
  std::vector<ReplicatedChange> changes;
};

// ApplyLoggedBatch writes a primary's batch `data` (first key at
// `sequence`) into a follower's `storage`, together with the new applied
// sequence (AppliedSequence) in the same atomic, synced write, so that after
// a crash the follower resumes exactly after the last batch it kept; then
// reloads the store's counters (Storage::ReloadCounters). Returns the model
// puts and deletes, for the in-memory index. Precondition: the follower's
// database was copied from the primary (same column families). INVALID_ARGUMENT
// for bytes that are not a write batch; DATA_LOSS for a stored model that
// does not parse; the store's errors. Cost: one synced write + the
// batch's size. Call under the caller's writer lock (batches apply in
// order).
absl::StatusOr<AppliedBatch> ApplyLoggedBatch(Storage& storage,
                                              const std::string& data,
                                              uint64_t sequence);

// AppliedSequence returns the primary sequence number a follower's store
// reflects, or nullopt when the store is not a follower's (never was one,
// or was promoted). Cost: one lookup. Thread-safe.
absl::StatusOr<std::optional<uint64_t>> AppliedSequence(const Storage& storage);

// SetAppliedSequence records `sequence` as applied (synced), e.g. the
// sequence of the checkpoint a follower starts from. Thread-safe.
absl::Status SetAppliedSequence(Storage& storage, uint64_t sequence);

// ClearAppliedSequence removes the record and the followed primary's
// identity (promotion: the store is a primary's from then on). Synced.
// Thread-safe.
absl::Status ClearAppliedSequence(Storage& storage);

// DatabaseIdentity returns `storage`'s database identity (RocksDB
// GetDbIdentity: a UUID made when the database is created). Every database
// copy a follower makes and every restore gets a new one
// (ForgetDatabaseIdentity), so sequence numbers are only compared between a
// follower and the very database it copied. Errors: the store's. Cost: a
// small file read. Thread-safe.
absl::StatusOr<std::string> DatabaseIdentity(const Storage& storage);

// ForgetDatabaseIdentity removes the identity file of the database copy in
// `data_dir` (a follower's checkpoint copy, a restored backup) before it is
// first opened, so that RocksDB gives the copy an identity of its own (the
// identity lives in that file only: Storage never sets
// write_dbid_to_manifest). Absent file: OK. UNAVAILABLE when it cannot be
// removed. Not thread-safe with an open database in `data_dir`.
absl::Status ForgetDatabaseIdentity(const std::string& data_dir);

// SetPrimaryIdentity records, in a follower's store, the identity of the
// primary database it copied (synced); PrimaryIdentity reads it ("" when
// none was recorded: a store copied before identities were kept, which is
// then not checked). Errors: the store's. Thread-safe.
absl::Status SetPrimaryIdentity(Storage& storage, const std::string& identity);
absl::StatusOr<std::string> PrimaryIdentity(const Storage& storage);

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_REPLICATION_H_
