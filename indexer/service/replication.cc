#include "indexer/service/replication.h"

#include <chrono>
#include <filesystem>
#include <memory>
#include <utility>

#include "absl/base/const_init.h"
#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "common/status_macros.h"
#include "rocksdb/db.h"
#include "rocksdb/transaction_log.h"
#include "rocksdb/utilities/backup_engine.h"
#include "rocksdb/utilities/checkpoint.h"
#include "rocksdb/write_batch.h"

namespace tpr::indexer {
namespace {

// The follower's record of the last primary sequence it applied, in the
// meta family (storage.h lists the other keys). Written in the same batch
// as the primary's writes it follows.
constexpr char kAppliedSeqKey[] = "replica_applied_seq";
// The follower's record of the primary database it copied (its identity).
constexpr char kPrimaryIdentityKey[] = "replica_primary_identity";

// RocksDB's status as ours: what failed, and RocksDB's reason.
absl::Status Rocks(const rocksdb::Status& s, absl::string_view what) {
  if (s.ok()) return absl::OkStatus();
  const std::string message = absl::StrCat(what, ": ", s.ToString());
  if (s.IsCorruption()) return absl::DataLossError(message);
  if (s.IsNotFound()) return absl::NotFoundError(message);
  if (s.IsInvalidArgument()) return absl::InvalidArgumentError(message);
  if (s.IsIOError() || s.IsBusy() || s.IsTryAgain())
    return absl::UnavailableError(message);
  return absl::InternalError(message);
}

std::string EncodeU64(uint64_t v) {
  std::string out(8, '\0');
  for (int i = 0; i < 8; ++i) out[i] = static_cast<char>((v >> (8 * i)) & 0xff);
  return out;
}

uint64_t DecodeU64(const std::string& s) {
  uint64_t v = 0;
  for (int i = 0; i < 8; ++i)
    v |= static_cast<uint64_t>(static_cast<unsigned char>(s[i])) << (8 * i);
  return v;
}

// Bytes of the regular files under `dir` (0 when absent).
uint64_t TreeBytes(const std::string& dir) {
  uint64_t total = 0;
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(dir, ec);
       !ec && it != std::filesystem::recursive_directory_iterator();
       it.increment(ec)) {
    std::error_code size_ec;
    if (it->is_regular_file(size_ec)) total += it->file_size(size_ec);
  }
  return total;
}

bool Inside(const std::filesystem::path& child,
            const std::filesystem::path& parent) {
  std::error_code ec;
  const auto c = std::filesystem::weakly_canonical(child, ec);
  const auto p = std::filesystem::weakly_canonical(parent, ec);
  auto ci = c.begin();
  for (auto pi = p.begin(); pi != p.end(); ++pi, ++ci) {
    if (pi->empty()) continue;  // a trailing separator
    if (ci == c.end() || *ci != *pi) return false;
  }
  return true;
}

// Collects the model puts and deletes of a replicated batch.
class ChangeCollector : public rocksdb::WriteBatch::Handler {
 public:
  explicit ChangeCollector(uint32_t models_family)
      : models_family_(models_family) {}

  rocksdb::Status PutCF(uint32_t family, const rocksdb::Slice& key,
                        const rocksdb::Slice& value) override {
    if (family != models_family_) return rocksdb::Status::OK();
    ReplicatedChange change;
    change.id = key.ToString();
    tpr::v1::Model model;
    // Storage's value layout: 8-byte write sequence, then the model.
    if (value.size() < 8 ||
        !model.ParseFromArray(value.data() + 8,
                              static_cast<int>(value.size() - 8))) {
      error_ = absl::DataLossError(
          absl::StrCat("replicated model '", change.id, "' does not parse"));
      return rocksdb::Status::Corruption("model does not parse");
    }
    change.model = std::move(model);
    changes_.push_back(std::move(change));
    return rocksdb::Status::OK();
  }
  rocksdb::Status DeleteCF(uint32_t family,
                           const rocksdb::Slice& key) override {
    if (family == models_family_)
      changes_.push_back({key.ToString(), std::nullopt});
    return rocksdb::Status::OK();
  }
  rocksdb::Status SingleDeleteCF(uint32_t family,
                                 const rocksdb::Slice& key) override {
    return DeleteCF(family, key);
  }
  rocksdb::Status DeleteRangeCF(uint32_t family, const rocksdb::Slice&,
                                const rocksdb::Slice&) override {
    if (family != models_family_) return rocksdb::Status::OK();
    // Storage never writes range deletions; a follower cannot mirror one
    // into its index without a scan.
    error_ = absl::InternalError(
        "replicated batch holds a range deletion of models");
    return rocksdb::Status::NotSupported("range deletion");
  }
  rocksdb::Status MergeCF(uint32_t family, const rocksdb::Slice&,
                          const rocksdb::Slice&) override {
    if (family != models_family_) return rocksdb::Status::OK();
    error_ = absl::InternalError("replicated batch holds a merge of models");
    return rocksdb::Status::NotSupported("merge");
  }

  std::vector<ReplicatedChange>& changes() { return changes_; }
  const absl::Status& error() const { return error_; }

 private:
  const uint32_t models_family_;
  std::vector<ReplicatedChange> changes_;
  absl::Status error_;
};

}  // namespace

absl::StatusOr<BackupResult> CreateBackup(Storage& storage,
                                          const std::string& backup_dir,
                                          int keep_last) {
  if (backup_dir.empty())
    return absl::InvalidArgumentError("backup_dir is empty");
  if (Inside(backup_dir, storage.dir())) {
    return absl::InvalidArgumentError(absl::StrCat(
        "backup_dir '", backup_dir, "' lies inside the data directory"));
  }
  // One writer per backup set (RocksDB's rule); backups are rare, so one
  // lock for the process is enough.
  static absl::Mutex backup_mu(absl::kConstInit);
  absl::MutexLock lock(&backup_mu);
  std::error_code ec;
  std::filesystem::create_directories(backup_dir, ec);
  if (ec) {
    return absl::UnavailableError(absl::StrCat(
        "cannot create backup_dir '", backup_dir, "': ", ec.message()));
  }
  rocksdb::BackupEngine* raw = nullptr;
  TPR_RETURN_IF_ERROR(Rocks(rocksdb::BackupEngine::Open(
                                rocksdb::Env::Default(),
                                rocksdb::BackupEngineOptions(backup_dir), &raw),
                            "cannot open the backup set"));
  std::unique_ptr<rocksdb::BackupEngine> engine(raw);
  const uint64_t before = TreeBytes(backup_dir);
  rocksdb::CreateBackupOptions options;
  // Memtables are flushed first, so the backup holds table files only and
  // no write-ahead log.
  options.flush_before_backup = true;
  rocksdb::BackupID id = 0;
  TPR_RETURN_IF_ERROR(
      Rocks(engine->CreateNewBackupWithMetadata(options, storage.rocks().db,
                                                "tpr-indexer", &id),
            "backup failed"));
  // Verified: every file's size and checksum re-read from the set.
  if (rocksdb::IOStatus v =
          engine->VerifyBackup(id, /*verify_with_checksum=*/true);
      !v.ok()) {
    return absl::DataLossError(
        absl::StrCat("backup ", id, " failed verification: ", v.ToString()));
  }
  rocksdb::BackupInfo info;
  TPR_RETURN_IF_ERROR(
      Rocks(engine->GetBackupInfo(id, &info), "cannot read the backup"));
  if (keep_last > 0) {
    TPR_RETURN_IF_ERROR(
        Rocks(engine->PurgeOldBackups(static_cast<uint32_t>(keep_last)),
              "cannot delete old backups"));
  }
  BackupResult result;
  result.backup_id = id;
  result.size_bytes = info.size;
  result.files = info.number_files;
  const uint64_t after = TreeBytes(backup_dir);
  result.copied_bytes = after > before ? after - before : 0;
  result.unix_seconds = info.timestamp;
  return result;
}

absl::StatusOr<RestoreResult> RestoreBackup(const std::string& backup_dir,
                                            uint32_t backup_id,
                                            const std::string& data_dir) {
  if (backup_dir.empty())
    return absl::InvalidArgumentError("backup_dir is empty");
  if (data_dir.empty()) return absl::InvalidArgumentError("data_dir is empty");
  std::error_code ec;
  if (std::filesystem::exists(data_dir, ec)) {
    if (!std::filesystem::is_directory(data_dir, ec)) {
      return absl::FailedPreconditionError(absl::StrCat(
          "'", data_dir, "' is not a directory; restore needs an empty one"));
    }
    if (!std::filesystem::is_empty(data_dir, ec)) {
      return absl::FailedPreconditionError(
          absl::StrCat("data directory '", data_dir,
                       "' is not empty; restore only into an empty or absent "
                       "directory (nothing was changed)"));
    }
  }
  if (!std::filesystem::exists(backup_dir + "/meta", ec)) {
    return absl::NotFoundError(
        absl::StrCat("no backup set in '", backup_dir, "'"));
  }
  rocksdb::BackupEngineReadOnly* raw = nullptr;
  TPR_RETURN_IF_ERROR(Rocks(rocksdb::BackupEngineReadOnly::Open(
                                rocksdb::Env::Default(),
                                rocksdb::BackupEngineOptions(backup_dir), &raw),
                            "cannot open the backup set"));
  std::unique_ptr<rocksdb::BackupEngineReadOnly> engine(raw);
  if (backup_id == 0) {
    rocksdb::BackupInfo latest;
    rocksdb::Status s = engine->GetLatestBackupInfo(&latest);
    if (s.IsNotFound()) {
      return absl::NotFoundError(
          absl::StrCat("backup set '", backup_dir, "' holds no backup"));
    }
    TPR_RETURN_IF_ERROR(Rocks(s, "cannot read the backup set"));
    backup_id = latest.backup_id;
  } else {
    rocksdb::BackupInfo info;
    if (!engine->GetBackupInfo(backup_id, &info).ok()) {
      return absl::NotFoundError(absl::StrCat("backup set '", backup_dir,
                                              "' holds no backup ", backup_id));
    }
  }
  if (rocksdb::IOStatus v =
          engine->VerifyBackup(backup_id, /*verify_with_checksum=*/true);
      !v.ok()) {
    return absl::DataLossError(absl::StrCat(
        "backup ", backup_id, " failed verification: ", v.ToString()));
  }
  std::filesystem::create_directories(data_dir, ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat("cannot create '", data_dir, "': ", ec.message()));
  }
  TPR_RETURN_IF_ERROR(
      Rocks(engine->RestoreDBFromBackup(backup_id, data_dir, data_dir),
            "restore failed"));
  // A restored database is a new history: followers of the original must
  // not tail it (their sequence numbers are the original's), so it gets an
  // identity of its own when first opened.
  TPR_RETURN_IF_ERROR(ForgetDatabaseIdentity(data_dir));
  return RestoreResult{backup_id};
}

absl::StatusOr<uint64_t> CreateCheckpoint(Storage& storage,
                                          const std::string& dir) {
  rocksdb::Checkpoint* raw = nullptr;
  TPR_RETURN_IF_ERROR(
      Rocks(rocksdb::Checkpoint::Create(storage.rocks().db, &raw),
            "cannot start a checkpoint"));
  std::unique_ptr<rocksdb::Checkpoint> checkpoint(raw);
  uint64_t sequence = 0;
  // log_size_for_flush 0: always flush first. The returned number is "part
  // of the checkpoint, not necessarily the latest": a follower may replay a
  // few batches the copy already holds, which is harmless because every
  // batch Storage writes sets absolute values (puts and deletes, no merges).
  TPR_RETURN_IF_ERROR(Rocks(checkpoint->CreateCheckpoint(dir, 0, &sequence),
                            "cannot create a checkpoint"));
  return sequence;
}

uint64_t LatestSequence(const Storage& storage) {
  return storage.rocks().db->GetLatestSequenceNumber();
}

struct LogCursor::Iterator {
  std::unique_ptr<rocksdb::TransactionLogIterator> it;
};

LogCursor::LogCursor(Storage& storage, uint64_t from)
    : storage_(storage), next_(from), it_(std::make_unique<Iterator>()) {}

LogCursor::~LogCursor() = default;

absl::StatusOr<std::vector<LoggedBatch>> LogCursor::Read(size_t max_bytes) {
  std::vector<LoggedBatch> out;
  rocksdb::DB* db = storage_.rocks().db;
  if (next_ > db->GetLatestSequenceNumber()) return out;
  const auto purged = [&](uint64_t first) {
    return absl::OutOfRangeError(
        absl::StrCat("sequence ", next_,
                     " is no longer in the kept write-ahead log (it starts at ",
                     first, "); start again from a checkpoint"));
  };
  std::unique_ptr<rocksdb::TransactionLogIterator>& it = it_->it;
  // Two rounds at most: the open iterator, then (when it had nothing: a new
  // log file was started, or it failed) a fresh one.
  for (int round = 0; round < 2; ++round) {
    const bool fresh = it == nullptr;
    if (fresh) {
      rocksdb::Status s = db->GetUpdatesSince(next_, &it);
      if (s.IsNotFound() || s.IsTryAgain()) {
        it.reset();
        return purged(0);
      }
      if (!s.ok()) {
        it.reset();
        return Rocks(s, "cannot read the write-ahead log");
      }
    } else if (!it->Valid()) {
      // At the end of what it had read: read on from there (RocksDB
      // re-reads the end of the current log file). With a non-OK status
      // (a new log file it cannot see, a gap) this does nothing.
      it->Next();
    }
    size_t bytes = 0;
    bool seen = false;
    bool stale = false;
    while (it->Valid()) {
      seen = true;
      rocksdb::BatchResult batch = it->GetBatch();
      it->Next();  // GetBatch moved the batch out: never look at it twice
      const uint32_t count =
          static_cast<uint32_t>(batch.writeBatchPtr->Count());
      if (batch.sequence + count <= next_)
        continue;  // before next_: sent already
      if (batch.sequence > next_) {
        // The log between is missing: deleted (a fresh iterator starts at
        // the oldest kept batch), or this iterator skipped (reopen).
        if (fresh && out.empty()) {
          it.reset();
          return purged(batch.sequence);
        }
        stale = true;
        break;
      }
      out.push_back({batch.sequence, count, batch.writeBatchPtr->Data()});
      next_ = batch.sequence + count;
      bytes += out.back().data.size();
      if (bytes >= max_bytes) break;
    }
    if (stale) it.reset();
    if (!out.empty()) return out;
    const rocksdb::Status status =
        it == nullptr ? rocksdb::Status::OK() : it->status();
    if (fresh) {
      it.reset();
      if (!status.ok() && !status.IsTryAgain()) {
        return Rocks(status, "cannot read the write-ahead log");
      }
      // `next_` was written (it is at most the latest) but no kept log
      // holds it.
      if (!seen) return purged(0);
      return out;
    }
    it.reset();  // nothing new from the open iterator: look again afresh
  }
  return out;
}

absl::StatusOr<AppliedBatch> ApplyLoggedBatch(Storage& storage,
                                              const std::string& data,
                                              uint64_t sequence) {
  if (data.size() < 12) {
    return absl::InvalidArgumentError(
        absl::StrCat("replicated batch at ", sequence, " is ", data.size(),
                     " bytes: too short"));
  }
  rocksdb::WriteBatch batch(data);
  const RocksHandles h = storage.rocks();
  AppliedBatch applied;
  applied.last_sequence = sequence + batch.Count() - 1;
  ChangeCollector collector(h.models->GetID());
  rocksdb::Status iterated = batch.Iterate(&collector);
  if (!collector.error().ok()) return collector.error();
  if (!iterated.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("replicated batch at ", sequence,
                     " does not parse: ", iterated.ToString()));
  }
  TPR_RETURN_IF_ERROR(
      Rocks(batch.Put(h.meta, kAppliedSeqKey, EncodeU64(applied.last_sequence)),
            "cannot extend the replicated batch"));
  rocksdb::WriteOptions w;
  w.sync = true;
  TPR_RETURN_IF_ERROR(
      Rocks(h.db->Write(w, &batch), "cannot apply a replicated batch"));
  TPR_RETURN_IF_ERROR(storage.ReloadCounters());
  applied.changes = std::move(collector.changes());
  return applied;
}

absl::StatusOr<std::optional<uint64_t>> AppliedSequence(
    const Storage& storage) {
  const RocksHandles h = storage.rocks();
  std::string value;
  rocksdb::Status s =
      h.db->Get(rocksdb::ReadOptions(), h.meta, kAppliedSeqKey, &value);
  if (s.IsNotFound()) return std::optional<uint64_t>();
  TPR_RETURN_IF_ERROR(Rocks(s, "cannot read the applied sequence"));
  if (value.size() != 8)
    return absl::DataLossError("the applied sequence is malformed");
  return std::optional<uint64_t>(DecodeU64(value));
}

absl::Status SetAppliedSequence(Storage& storage, uint64_t sequence) {
  const RocksHandles h = storage.rocks();
  rocksdb::WriteOptions w;
  w.sync = true;
  return Rocks(h.db->Put(w, h.meta, kAppliedSeqKey, EncodeU64(sequence)),
               "cannot record the applied sequence");
}

absl::Status ClearAppliedSequence(Storage& storage) {
  const RocksHandles h = storage.rocks();
  rocksdb::WriteBatch batch;
  TPR_RETURN_IF_ERROR(
      Rocks(batch.Delete(h.meta, kAppliedSeqKey), "cannot clear"));
  TPR_RETURN_IF_ERROR(
      Rocks(batch.Delete(h.meta, kPrimaryIdentityKey), "cannot clear"));
  rocksdb::WriteOptions w;
  w.sync = true;
  return Rocks(h.db->Write(w, &batch), "cannot clear the applied sequence");
}

absl::StatusOr<std::string> DatabaseIdentity(const Storage& storage) {
  std::string identity;
  TPR_RETURN_IF_ERROR(Rocks(storage.rocks().db->GetDbIdentity(identity),
                            "cannot read the database identity"));
  return identity;
}

absl::Status ForgetDatabaseIdentity(const std::string& data_dir) {
  std::error_code ec;
  std::filesystem::remove(data_dir + "/IDENTITY", ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat("cannot remove ", data_dir, "/IDENTITY: ", ec.message()));
  }
  return absl::OkStatus();
}

absl::Status SetPrimaryIdentity(Storage& storage, const std::string& identity) {
  const RocksHandles h = storage.rocks();
  rocksdb::WriteOptions w;
  w.sync = true;
  return Rocks(h.db->Put(w, h.meta, kPrimaryIdentityKey, identity),
               "cannot record the primary's identity");
}

absl::StatusOr<std::string> PrimaryIdentity(const Storage& storage) {
  const RocksHandles h = storage.rocks();
  std::string value;
  rocksdb::Status s =
      h.db->Get(rocksdb::ReadOptions(), h.meta, kPrimaryIdentityKey, &value);
  if (s.IsNotFound()) return std::string();
  TPR_RETURN_IF_ERROR(Rocks(s, "cannot read the primary's identity"));
  return value;
}

}  // namespace tpr::indexer
