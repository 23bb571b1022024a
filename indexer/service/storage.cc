#include "indexer/service/storage.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <mutex>
#include <optional>
#include <thread>
#include <unordered_map>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "common/mutex.h"
#include "common/status_macros.h"
#include "indexer/service/ack_file.h"
#include "rocksdb/db.h"
#include "rocksdb/env.h"
#include "rocksdb/filter_policy.h"
#include "rocksdb/listener.h"
#include "rocksdb/options.h"
#include "rocksdb/statistics.h"
#include "rocksdb/table.h"
#include "rocksdb/write_batch.h"

namespace tpr::indexer {
namespace {

constexpr char kModelsFamily[] = "models";
constexpr char kMediaFamily[] = "media";
constexpr char kTreeKey[] = "tree";
constexpr char kTreeSeqKey[] = "tree_seq";
constexpr char kLastSeqKey[] = "last_seq";
constexpr char kModelCountKey[] = "model_count";
constexpr char kWriteCountKey[] = "write_count";

std::string EncodeSeq(uint64_t seq) {
  std::string out(8, '\0');
  for (int i = 0; i < 8; ++i)
    out[i] = static_cast<char>((seq >> (8 * i)) & 0xff);
  return out;
}

uint64_t DecodeSeq(const char* p) {
  uint64_t seq = 0;
  for (int i = 0; i < 8; ++i) {
    seq |= static_cast<uint64_t>(static_cast<unsigned char>(p[i])) << (8 * i);
  }
  return seq;
}

// Storage errors never name the server path (STYLE.md): the message says
// what failed and RocksDB's reason, which is about the files, not the
// caller; the data directory is cut from RocksDB's file names.
absl::Status FromRocks(const rocksdb::Status& s, absl::string_view what,
                       const std::string& dir = "") {
  if (s.ok()) return absl::OkStatus();
  std::string message = absl::StrCat(what, ": ", s.ToString());
  if (!dir.empty()) message = absl::StrReplaceAll(message, {{dir + "/", ""}});
  if (s.IsCorruption()) return absl::DataLossError(message);
  // Disk full: RESOURCE_EXHAUSTED, which clients do not retry (UNAVAILABLE
  // they do, and would hammer a full disk); Storage::WriteState recovers.
  if (s.IsNoSpace()) {
    return absl::ResourceExhaustedError(absl::StrCat(
        message, " (the disk is full; writes resume once space is freed)"));
  }
  if (s.IsNotFound()) return absl::NotFoundError(message);
  if (s.IsIOError() && s.ToString().find("lock") != std::string::npos) {
    return absl::UnavailableError(message);
  }
  if (s.IsIOError() || s.IsBusy() || s.IsTryAgain()) {
    return absl::UnavailableError(message);
  }
  return absl::InternalError(message);
}

absl::StatusOr<std::pair<uint64_t, tpr::v1::Model>> DecodeModel(
    const rocksdb::Slice& value, const rocksdb::Slice& key) {
  if (value.size() < 8) {
    return absl::DataLossError(
        absl::StrCat("stored model '", key.ToString(), "' is truncated"));
  }
  std::pair<uint64_t, tpr::v1::Model> out;
  out.first = DecodeSeq(value.data());
  if (!out.second.ParseFromArray(value.data() + 8,
                                 static_cast<int>(value.size() - 8))) {
    return absl::DataLossError(
        absl::StrCat("stored model '", key.ToString(), "' does not parse"));
  }
  return out;
}

// The files a data-loss message names: the MANIFEST that CURRENT points to
// and the write-ahead logs, by file name (docs/recovery.md says what to do).
std::string DescribeFiles(const std::string& dir) {
  std::string manifest = "no CURRENT file";
  std::vector<std::string> logs;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name.size() > 4 && name.compare(name.size() - 4, 4, ".log") == 0)
      logs.push_back(name);
  }
  std::sort(logs.begin(), logs.end());
  if (FILE* f = std::fopen((dir + "/CURRENT").c_str(), "r")) {
    char line[256] = {0};
    if (std::fgets(line, sizeof line, f) != nullptr) {
      manifest = line;
      while (!manifest.empty() &&
             (manifest.back() == '\n' || manifest.back() == '\r')) {
        manifest.pop_back();
      }
    }
    std::fclose(f);
  }
  return absl::StrCat(
      manifest, ", write-ahead log",
      logs.empty() ? "s: none" : absl::StrCat(": ", absl::StrJoin(logs, ", ")));
}

// What the meta family records about the models, written in the same batch
// as the models: the last model sequence number, the number of write
// batches and the model count.
struct Counters {
  uint64_t last_seq = 0;
  uint64_t writes = 0;
  std::optional<uint64_t> models;  // absent in databases written before it
};

absl::StatusOr<Counters> ReadCounters(rocksdb::DB* db,
                                      rocksdb::ColumnFamilyHandle* meta,
                                      const std::string& dir) {
  Counters out;
  std::string value;
  rocksdb::Status s =
      db->Get(rocksdb::ReadOptions(), meta, kLastSeqKey, &value);
  if (s.ok() && value.size() == 8) {
    out.last_seq = DecodeSeq(value.data());
  } else if (!s.ok() && !s.IsNotFound()) {
    return FromRocks(s, "cannot read the sequence counter", dir);
  }
  s = db->Get(rocksdb::ReadOptions(), meta, kModelCountKey, &value);
  if (s.ok() && value.size() == 8) {
    out.models = DecodeSeq(value.data());
  } else if (!s.ok() && !s.IsNotFound()) {
    return FromRocks(s, "cannot read the model count", dir);
  }
  s = db->Get(rocksdb::ReadOptions(), meta, kWriteCountKey, &value);
  if (s.ok() && value.size() == 8) {
    out.writes = DecodeSeq(value.data());
  } else if (!s.ok() && !s.IsNotFound()) {
    return FromRocks(s, "cannot read the write count", dir);
  }
  return out;
}

// The rule of docs/recovery.md: a database holding less than was
// acknowledged is never served. Fewer write batches than acknowledged means
// acknowledged writes are gone (a damaged MANIFEST or write-ahead log); the
// same number with a different model count means models are. More batches
// than acknowledged is a crash between a write and its record (the record
// follows the write), not a loss.
absl::Status CheckAgainstAcknowledged(const Acknowledged& ack,
                                      const Counters& db,
                                      const std::string& dir) {
  const bool writes_lost = db.writes < ack.writes;
  const bool models_lost = db.writes == ack.writes && db.models.has_value() &&
                           *db.models != ack.models;
  if (!writes_lost && !models_lost) return absl::OkStatus();
  return absl::DataLossError(absl::StrCat(
      "the database holds ", db.writes, " write batches (",
      db.models.has_value() ? absl::StrCat(*db.models) : std::string("unknown"),
      " models) but ", ack.writes, " (", ack.models,
      " models) were acknowledged (", AckFile::kName,
      "): acknowledged writes were lost from ", DescribeFiles(dir),
      "; refusing to serve a smaller database (see docs/recovery.md)"));
}

// The RocksDB options of both opens (read-only check, then read-write).
// Recovery and deletion are chosen for "never silently lose an
// acknowledged write" (docs/recovery.md):
// - wal_recovery_mode kTolerateCorruptedTailRecords: a record torn by a
//   crash at the very end of a log (never acknowledged: acknowledged writes
//   are synced whole) is dropped; any other corruption refuses the open.
//   RocksDB's default, kPointInTimeRecovery, stops replay silently at the
//   first bad record and serves what came before.
// - paranoid_checks (the default, stated): corruption found in reads or
//   table files fails instead of being skipped; a failed write stops writes.
// - best_efforts_recovery off (the default, stated): never fall back to an
//   older MANIFEST, which would serve an older database.
// - track_and_verify_wals_in_manifest: a closed write-ahead log that is
//   missing or shorter than the MANIFEST recorded refuses the open.
// - atomic_flush: the flushes of both families are recorded in the MANIFEST
//   as one group, so the meta family's counters always speak for the models
//   family (a MANIFEST cut between two flushes cannot keep one, lose the
//   other).
// - Deletion: a read-write open deletes every file the MANIFEST does not
//   list, so Open first opens read-only (which deletes nothing) and checks
//   the counters against ACKNOWLEDGED; a refused database keeps every file
//   for the recovery procedure.
// RocksDB's own diagnostics go to stderr, warnings and errors only, not to
// a LOG file in the data directory: on a full disk that file's writer fails
// too, and RocksDB (7.8, built with assertions as Debian ships it) aborts
// the process on its next log line (WritableFileWriter's "previous error"
// assertion, seen in indexer_disk_full_test). A diagnostic must not take
// the indexer down, nor compete with the data for the last bytes.
class StderrLogger : public rocksdb::Logger {
 public:
  StderrLogger() : rocksdb::Logger(rocksdb::InfoLogLevel::WARN_LEVEL) {}
  using rocksdb::Logger::Logv;
  void Logv(const char* format, va_list ap) override {
    char line[1024];
    std::vsnprintf(line, sizeof(line), format, ap);
    std::fprintf(stderr, "rocksdb: %s\n", line);
  }
};

rocksdb::Options DbOptions(const StorageOptions& options) {
  rocksdb::Options db_options;
  db_options.info_log = std::make_shared<StderrLogger>();
  db_options.create_if_missing = options.create_if_missing;
  db_options.create_missing_column_families = true;
  db_options.wal_recovery_mode =
      rocksdb::WALRecoveryMode::kTolerateCorruptedTailRecords;
  db_options.paranoid_checks = true;
  db_options.best_efforts_recovery = false;
  db_options.track_and_verify_wals_in_manifest = true;
  db_options.atomic_flush = true;
  // Two cores shared with the search threads: one flush, one compaction.
  db_options.IncreaseParallelism(2);
  // Followers tail the write-ahead log (replication.h): closed logs are
  // archived and kept this long / this large before deletion.
  db_options.WAL_ttl_seconds = options.wal_keep_seconds;
  db_options.WAL_size_limit_MB = options.wal_keep_mb;
  return db_options;
}

std::vector<rocksdb::ColumnFamilyDescriptor> Families() {
  // Signatures are ~15 KB of doubles that barely compress; a larger write
  // buffer means fewer flushes during bulk ingest. A Bloom filter keeps the
  // existence checks of Write (new ids miss) off the table files.
  rocksdb::ColumnFamilyOptions models_options;
  models_options.write_buffer_size = 64 << 20;
  models_options.compression = rocksdb::kNoCompression;
  rocksdb::BlockBasedTableOptions table;
  table.block_size = 32 << 10;
  table.filter_policy.reset(rocksdb::NewBloomFilterPolicy(10));
  models_options.table_factory.reset(rocksdb::NewBlockBasedTableFactory(table));
  rocksdb::ColumnFamilyOptions meta_options;
  meta_options.compression = rocksdb::kNoCompression;
  // PNGs are compressed already; read one model at a time.
  rocksdb::ColumnFamilyOptions media_options;
  media_options.compression = rocksdb::kNoCompression;
  return {{rocksdb::kDefaultColumnFamilyName, meta_options},
          {kModelsFamily, models_options},
          {kMediaFamily, media_options}};
}

// The families of Families() that the database in `dir` already has: a
// read-only open cannot create one, and a database written before the
// media family existed gets it at the read-write open.
std::vector<rocksdb::ColumnFamilyDescriptor> ExistingFamilies(
    const rocksdb::Options& options, const std::string& dir) {
  std::vector<std::string> names;
  std::vector<rocksdb::ColumnFamilyDescriptor> out;
  if (!rocksdb::DB::ListColumnFamilies(options, dir, &names).ok()) {
    return Families();  // the open reports the reason
  }
  for (rocksdb::ColumnFamilyDescriptor& family : Families()) {
    if (std::find(names.begin(), names.end(), family.name) != names.end()) {
      out.push_back(std::move(family));
    }
  }
  return out;
}

// Counts write stalls and times the write-ahead log's syncs for metrics
// (StorageOptions::on_wal_sync, EngineStats). File-I/O notifications are
// needed for the syncs; RocksDB then also reports reads and writes, which
// this listener ignores (a timestamp pair per I/O).
class EngineListener final : public rocksdb::EventListener {
 public:
  explicit EngineListener(std::function<void(double)> on_wal_sync)
      : on_wal_sync_(std::move(on_wal_sync)) {}

  void OnStallConditionsChanged(const rocksdb::WriteStallInfo& info) override {
    if (info.condition.cur == rocksdb::WriteStallCondition::kDelayed) ++delayed;
    if (info.condition.cur == rocksdb::WriteStallCondition::kStopped) ++stopped;
  }
  void OnFileSyncFinish(const rocksdb::FileOperationInfo& info) override {
    // Write-ahead logs are the *.log files (table files are *.sst).
    if (on_wal_sync_ && info.path.size() > 4 &&
        info.path.compare(info.path.size() - 4, 4, ".log") == 0) {
      on_wal_sync_(std::chrono::duration<double>(info.duration).count());
    }
  }
  bool ShouldBeNotifiedOnFileIO() override {
    return static_cast<bool>(on_wal_sync_);
  }

  std::atomic<uint64_t> delayed{0};
  std::atomic<uint64_t> stopped{0};

 private:
  const std::function<void(double)> on_wal_sync_;
};

}  // namespace

struct Storage::Impl {
  std::string dir;
  StorageOptions options;
  std::unique_ptr<rocksdb::DB> db;
  rocksdb::ColumnFamilyHandle* meta = nullptr;    // "default"
  rocksdb::ColumnFamilyHandle* models = nullptr;  // "models"
  rocksdb::ColumnFamilyHandle* media = nullptr;   // "media"
  // RocksDB's statistics and our listener (EngineStats), read-write open.
  std::shared_ptr<rocksdb::Statistics> statistics;
  std::shared_ptr<EngineListener> listener;
  // The mutexes here are std::mutex, which TSan sees (Debian's libabsl is
  // not instrumented, so TSan would see no lock around an absl::Mutex; the
  // rest of the indexer uses tpr::common::Mutex, common/mutex.h, which is a
  // standard-library lock in TSan builds). What each guards is written
  // beside it.
  //
  // Sequence numbers are assigned under this mutex so that the order of
  // numbers equals the order of the RocksDB writes that carry them; the
  // model count and the ACKNOWLEDGED record follow the same order.
  std::mutex write_mu;
  std::atomic<uint64_t> last_seq{0};
  std::atomic<uint64_t> model_count{0};
  std::atomic<uint64_t> writes{0};
  std::unique_ptr<AckFile> ack;
  // Set when a write failed for lack of space: RocksDB then refuses writes
  // until DB::Resume() succeeds (a background error). Cleared by Resume.
  std::atomic<bool> no_space{false};
  std::mutex resume_mu;
  std::chrono::steady_clock::time_point last_resume;  // guarded by resume_mu
  std::string no_space_reason;                        // guarded by resume_mu

  ~Impl() {
    if (db) {
      // A graceful close flushes the memtables, so that the next open has no
      // write-ahead log to replay (replaying up to a 64 MB memtable of
      // signatures, and flushing it again, was a visible part of reopen).
      // After a crash the log is replayed as usual.
      std::vector<rocksdb::ColumnFamilyHandle*> families;
      if (meta) families.push_back(meta);
      if (models) families.push_back(models);
      if (media) families.push_back(media);
      if (!families.empty()) {
        db->Flush(rocksdb::FlushOptions(), families).PermitUncheckedError();
      }
      // Unsynced writes were acknowledged without a record; the flush made
      // them durable, so the record catches up here.
      if (ack && !options.sync_writes) {
        ack->Record({writes.load(), model_count.load()}).IgnoreError();
      }
      if (meta) db->DestroyColumnFamilyHandle(meta);
      if (models) db->DestroyColumnFamilyHandle(models);
      if (media) db->DestroyColumnFamilyHandle(media);
      db->Close().PermitUncheckedError();
    }
  }

  void MarkNoSpace(const absl::Status& status) {
    std::lock_guard<std::mutex> lock(resume_mu);
    no_space_reason = std::string(status.message());
    last_resume = std::chrono::steady_clock::now();
    no_space = true;
  }

  rocksdb::WriteOptions WriteOpts() const {
    rocksdb::WriteOptions w;
    w.sync = options.sync_writes;
    return w;
  }
};

Storage::Storage(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Storage::~Storage() = default;

absl::StatusOr<std::unique_ptr<Storage>> Storage::Open(
    const std::string& dir, const StorageOptions& options) {
  if (dir.empty()) return absl::InvalidArgumentError("data directory is empty");
  if (options.create_if_missing) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) {
      return absl::UnavailableError(
          absl::StrCat("cannot create the data directory: ", ec.message()));
    }
  }
  auto impl = std::make_unique<Impl>();
  impl->dir = dir;
  impl->options = options;

  const bool existed = std::filesystem::exists(dir + "/CURRENT");
  absl::StatusOr<std::unique_ptr<AckFile>> ack =
      AckFile::Open(dir, options.create_if_missing);
  if (!ack.ok()) {
    if (absl::IsDataLoss(ack.status())) {
      return absl::DataLossError(
          absl::StrCat(ack.status().message(), "; see docs/recovery.md"));
    }
    return ack.status();
  }
  impl->ack = std::move(*ack);
  const std::optional<Acknowledged> acknowledged = impl->ack->recorded();
  const rocksdb::Options db_options = DbOptions(options);
  std::vector<rocksdb::ColumnFamilyHandle*> handles;
  rocksdb::DB* raw = nullptr;
  auto open_failed = [&dir](const rocksdb::Status& s) {
    absl::Status st = FromRocks(s, "cannot open the model database", dir);
    if (!absl::IsDataLoss(st)) return st;
    return absl::DataLossError(absl::StrCat(
        st.message(), " (", DescribeFiles(dir), "); see docs/recovery.md"));
  };
  if (acknowledged.has_value() && !existed) {
    return absl::DataLossError(absl::StrCat(
        "the database is gone (no CURRENT file) but ", acknowledged->writes,
        " write batches (", acknowledged->models,
        " models) were acknowledged (", AckFile::kName,
        "); refusing to start an empty database (see docs/recovery.md)"));
  }
  if (acknowledged.has_value()) {
    // The check before anything may be deleted (see DbOptions). A read-only
    // open takes no lock, so RocksDB's own lock is taken around it: a
    // directory in use by another process is UNAVAILABLE, never read while
    // it changes.
    rocksdb::Env* env = rocksdb::Env::Default();
    rocksdb::FileLock* lock = nullptr;
    rocksdb::Status s = env->LockFile(dir + "/LOCK", &lock);
    if (!s.ok()) return FromRocks(s, "cannot open the model database", dir);
    s = rocksdb::DB::OpenForReadOnly(
        db_options, dir, ExistingFamilies(db_options, dir), &handles, &raw);
    absl::Status checked;
    if (!s.ok()) {
      checked = open_failed(s);
    } else {
      std::unique_ptr<rocksdb::DB> db(raw);
      absl::StatusOr<Counters> counters =
          ReadCounters(db.get(), handles[0], dir);
      for (rocksdb::ColumnFamilyHandle* h : handles)
        db->DestroyColumnFamilyHandle(h);
      handles.clear();
      checked = counters.ok()
                    ? CheckAgainstAcknowledged(*acknowledged, *counters, dir)
                    : counters.status();
    }
    env->UnlockFile(lock).PermitUncheckedError();
    TPR_RETURN_IF_ERROR(checked);
  }

  // Statistics (tickers only: no timers, whose clock reads cost on every
  // operation) and the listener, on the serving open.
  rocksdb::Options serving_options = db_options;
  serving_options.statistics = rocksdb::CreateDBStatistics();
  serving_options.statistics->set_stats_level(
      rocksdb::StatsLevel::kExceptHistogramOrTimers);
  impl->statistics = serving_options.statistics;
  impl->listener = std::make_shared<EngineListener>(options.on_wal_sync);
  serving_options.listeners.push_back(impl->listener);
  rocksdb::Status s =
      rocksdb::DB::Open(serving_options, dir, Families(), &handles, &raw);
  if (!s.ok()) return open_failed(s);
  impl->db.reset(raw);
  impl->meta = handles[0];
  impl->models = handles[1];
  impl->media = handles[2];

  // The next sequence number continues after everything on disk: every
  // model write records the last number it used in the same atomic batch, so
  // no scan is needed (the tree marker is never above it).
  absl::StatusOr<Counters> counters =
      ReadCounters(impl->db.get(), impl->meta, dir);
  if (!counters.ok()) return counters.status();
  if (acknowledged.has_value()) {
    TPR_RETURN_IF_ERROR(
        CheckAgainstAcknowledged(*acknowledged, *counters, dir));
  }
  if (!counters->models.has_value()) {
    // A database written before the model count existed (or a new one):
    // count once and record it, so every later open can check.
    uint64_t n = 0;
    std::unique_ptr<rocksdb::Iterator> it(
        impl->db->NewIterator(rocksdb::ReadOptions(), impl->models));
    for (it->SeekToFirst(); it->Valid(); it->Next()) ++n;
    TPR_RETURN_IF_ERROR(
        FromRocks(it->status(), "cannot count the models", dir));
    rocksdb::WriteBatch batch;
    batch.Put(impl->meta, kModelCountKey, EncodeSeq(n));
    rocksdb::WriteOptions w;
    w.sync = true;
    TPR_RETURN_IF_ERROR(FromRocks(impl->db->Write(w, &batch),
                                  "cannot record the model count", dir));
    counters->models = n;
  }
  impl->last_seq = counters->last_seq;
  impl->writes = counters->writes;
  impl->model_count = *counters->models;
  if (!acknowledged.has_value() || acknowledged->writes != counters->writes ||
      acknowledged->models != *counters->models) {
    // New file (new or older database), or a crash between a write and its
    // record (the database is then ahead, never behind: checked above).
    TPR_RETURN_IF_ERROR(
        impl->ack->Record({counters->writes, *counters->models}));
  }
  return std::unique_ptr<Storage>(new Storage(std::move(impl)));
}

absl::Status Storage::Write(const std::vector<ModelWrite>& writes) {
  if (writes.empty()) return absl::OkStatus();
  if (impl_->no_space.load()) TPR_RETURN_IF_ERROR(WriteState());
  std::lock_guard<std::mutex> lock(impl_->write_mu);
  uint64_t seq = impl_->last_seq.load();
  int64_t models = static_cast<int64_t>(impl_->model_count.load());
  const auto started = std::chrono::steady_clock::now();
  // Whether each id is stored, as of this batch's earlier writes: the model
  // count changes by puts of new ids and deletes of stored ones.
  std::unordered_map<std::string, bool> present;
  auto stored = [&](const std::string& id) -> absl::StatusOr<bool> {
    auto it = present.find(id);
    if (it != present.end()) return it->second;
    rocksdb::PinnableSlice value;
    rocksdb::Status s =
        impl_->db->Get(rocksdb::ReadOptions(), impl_->models, id, &value);
    if (s.IsNotFound()) return false;
    if (!s.ok()) return FromRocks(s, "cannot read a model", impl_->dir);
    return true;
  };
  rocksdb::WriteBatch batch;
  std::string value;
  for (const ModelWrite& w : writes) {
    absl::StatusOr<bool> was = stored(w.id);
    if (!was.ok()) return was.status();
    if (w.model == nullptr) {
      batch.Delete(impl_->models, w.id);
      batch.Delete(impl_->media, w.id);
      if (*was) --models;
      present[w.id] = false;
      continue;
    }
    value = EncodeSeq(++seq);
    if (!w.model->AppendToString(&value)) {
      return absl::InternalError(
          absl::StrCat("cannot serialize model '", w.id, "'"));
    }
    batch.Put(impl_->models, w.id, value);
    if (w.media != nullptr && (!w.media->thumbnail_png().empty() ||
                               !w.media->preview_ply().empty())) {
      if (!w.media->SerializeToString(&value)) {
        return absl::InternalError(
            absl::StrCat("cannot serialize the media of model '", w.id, "'"));
      }
      batch.Put(impl_->media, w.id, value);
    } else {
      batch.Delete(impl_->media, w.id);
    }
    if (!*was) ++models;
    present[w.id] = true;
  }
  batch.Put(impl_->meta, kLastSeqKey, EncodeSeq(seq));
  batch.Put(impl_->meta, kModelCountKey,
            EncodeSeq(static_cast<uint64_t>(models)));
  // Every batch, deletes included, counts one write, so that a crash between
  // a write and its ACKNOWLEDGED record leaves the database ahead of the
  // record (see CheckAgainstAcknowledged).
  const uint64_t writes_after = impl_->writes.load() + 1;
  batch.Put(impl_->meta, kWriteCountKey, EncodeSeq(writes_after));
  rocksdb::Status s = impl_->db->Write(impl_->WriteOpts(), &batch);
  if (!s.ok()) {
    absl::Status st = FromRocks(s, "cannot write models", impl_->dir);
    if (absl::IsResourceExhausted(st)) impl_->MarkNoSpace(st);
    return st;
  }
  impl_->last_seq = seq;
  impl_->writes = writes_after;
  impl_->model_count = static_cast<uint64_t>(models);
  // The record follows the synced write: the database is never behind it.
  // Without sync_writes nothing is durable yet; the record is written at
  // close, after the flush.
  if (impl_->options.sync_writes) {
    TPR_RETURN_IF_ERROR(
        impl_->ack->Record({writes_after, static_cast<uint64_t>(models)}));
  }
  if (impl_->options.on_write) {
    impl_->options.on_write(std::chrono::duration<double>(
                                std::chrono::steady_clock::now() - started)
                                .count());
  }
  return absl::OkStatus();
}

absl::StatusOr<tpr::v1::Model> Storage::GetModel(const std::string& id) const {
  rocksdb::PinnableSlice value;
  rocksdb::Status s =
      impl_->db->Get(rocksdb::ReadOptions(), impl_->models, id, &value);
  if (s.IsNotFound())
    return absl::NotFoundError(absl::StrCat("no model with id '", id, "'"));
  if (!s.ok()) return FromRocks(s, "cannot read a model");
  auto decoded = DecodeModel(value, id);
  if (!decoded.ok()) return decoded.status();
  return std::move(decoded->second);
}

absl::StatusOr<tpr::v1::ModelMedia> Storage::GetMedia(
    const std::string& id) const {
  rocksdb::PinnableSlice value;
  rocksdb::Status s =
      impl_->db->Get(rocksdb::ReadOptions(), impl_->media, id, &value);
  if (s.IsNotFound()) {
    return absl::NotFoundError(absl::StrCat("no media for id '", id, "'"));
  }
  if (!s.ok()) return FromRocks(s, "cannot read media");
  tpr::v1::ModelMedia media;
  if (!media.ParseFromArray(value.data(), static_cast<int>(value.size()))) {
    return absl::DataLossError(
        absl::StrCat("stored media of model '", id, "' do not parse"));
  }
  return media;
}

absl::Status Storage::ForEachModel(
    const std::function<absl::Status(uint64_t, tpr::v1::Model&&)>& fn,
    int threads) const {
  rocksdb::ReadOptions read;
  // A full scan should not evict hot blocks; it reads each block once.
  read.fill_cache = false;
  read.readahead_size = 2 << 20;
  std::unique_ptr<rocksdb::Iterator> it(
      impl_->db->NewIterator(read, impl_->models));
  if (threads <= 1) {
    for (it->SeekToFirst(); it->Valid(); it->Next()) {
      auto decoded = DecodeModel(it->value(), it->key());
      if (!decoded.ok()) return decoded.status();
      absl::Status st = fn(decoded->first, std::move(decoded->second));
      if (!st.ok()) return st;
    }
    return FromRocks(it->status(), "cannot scan the models");
  }

  // Parallel: this thread scans and copies raw records into chunks; workers
  // parse them and call fn. Parsing (about 14 KB of packed doubles per
  // model) and the caller's conversion cost far more than the scan, so the
  // scan keeps up; a bounded queue caps the memory held in flight.
  using Chunk = std::vector<std::pair<std::string, std::string>>;  // key, value
  constexpr size_t kChunk = 128;
  constexpr size_t kMaxQueued = 8;
  std::mutex mu;                  // std::mutex for TSan, as in Storage::Impl
  std::condition_variable ready;  // a chunk was queued, or the scan ended
  std::condition_variable room;   // a chunk was taken
  std::deque<Chunk> queue;        // guarded by mu
  bool scan_done = false;         // guarded by mu
  absl::Status first_error;       // guarded by mu
  std::atomic<bool> failed{false};
  auto record = [&](absl::Status st) {
    std::lock_guard<std::mutex> lock(mu);
    if (first_error.ok()) first_error = std::move(st);
    failed = true;
    room.notify_all();
  };
  auto work = [&] {
    for (;;) {
      Chunk chunk;
      {
        std::unique_lock<std::mutex> lock(mu);
        ready.wait(lock, [&] { return !queue.empty() || scan_done || failed; });
        if (failed || queue.empty()) return;
        chunk = std::move(queue.front());
        queue.pop_front();
        room.notify_one();
      }
      for (auto& [key, value] : chunk) {
        if (failed) return;
        auto decoded = DecodeModel(value, key);
        absl::Status st = decoded.ok()
                              ? fn(decoded->first, std::move(decoded->second))
                              : decoded.status();
        if (!st.ok()) {
          record(std::move(st));
          ready.notify_all();
          return;
        }
      }
    }
  };
  std::vector<std::thread> workers;
  for (int i = 0; i < threads; ++i) workers.emplace_back(work);
  Chunk chunk;
  chunk.reserve(kChunk);
  auto push = [&] {
    std::unique_lock<std::mutex> lock(mu);
    room.wait(lock, [&] { return queue.size() < kMaxQueued || failed; });
    queue.push_back(std::move(chunk));
    chunk = Chunk();
    chunk.reserve(kChunk);
    ready.notify_one();
  };
  for (it->SeekToFirst(); it->Valid() && !failed; it->Next()) {
    chunk.emplace_back(it->key().ToString(), it->value().ToString());
    if (chunk.size() == kChunk) push();
  }
  if (!chunk.empty() && !failed) push();
  {
    std::lock_guard<std::mutex> lock(mu);
    scan_done = true;
  }
  ready.notify_all();
  for (std::thread& w : workers) w.join();
  if (!first_error.ok()) return first_error;
  return FromRocks(it->status(), "cannot scan the models");
}

absl::Status Storage::SaveTree(const std::string& tree_bytes, uint64_t seq) {
  rocksdb::WriteBatch batch;
  batch.Put(impl_->meta, kTreeKey, tree_bytes);
  batch.Put(impl_->meta, kTreeSeqKey, EncodeSeq(seq));
  rocksdb::WriteOptions w;
  w.sync = true;
  // In ThreadSanitizer builds only, the tree save waits for the model
  // writes (write_mu), so that RocksDB never groups two of our threads'
  // batches into one write: the group's leader copies the other threads'
  // WriteBatch bytes after a hand-off through RocksDB's uninstrumented
  // atomics, which TSan reports as a race on those bytes with our frames on
  // top (seen: TreePersister::PersistNow against IndexerCore::
  // WriteGroupLocked). Normal builds keep saves and writes apart: a save of
  // a large tree must not stall writers.
  std::unique_lock<std::mutex> serialized(impl_->write_mu, std::defer_lock);
  if (tpr::common::kStdSync) serialized.lock();
  absl::Status st = FromRocks(impl_->db->Write(w, &batch),
                              "cannot persist the VP-tree", impl_->dir);
  if (absl::IsResourceExhausted(st)) impl_->MarkNoSpace(st);
  return st;
}

absl::StatusOr<PersistedTree> Storage::LoadTree() const {
  PersistedTree tree;
  std::string seq;
  // Read both keys from one snapshot: they were written in one batch.
  const rocksdb::Snapshot* snapshot = impl_->db->GetSnapshot();
  rocksdb::ReadOptions read;
  read.snapshot = snapshot;
  rocksdb::Status s1 = impl_->db->Get(read, impl_->meta, kTreeKey, &tree.bytes);
  rocksdb::Status s2 = impl_->db->Get(read, impl_->meta, kTreeSeqKey, &seq);
  impl_->db->ReleaseSnapshot(snapshot);
  if (s1.IsNotFound() || s2.IsNotFound()) {
    return absl::NotFoundError("no VP-tree persisted yet");
  }
  if (!s1.ok()) return FromRocks(s1, "cannot read the VP-tree");
  if (!s2.ok()) return FromRocks(s2, "cannot read the VP-tree marker");
  if (seq.size() != 8)
    return absl::DataLossError("VP-tree marker is malformed");
  tree.seq = DecodeSeq(seq.data());
  return tree;
}

uint64_t Storage::last_seq() const { return impl_->last_seq.load(); }

absl::Status Storage::WriteState() {
  if (!impl_->no_space.load()) return absl::OkStatus();
  std::lock_guard<std::mutex> lock(impl_->resume_mu);
  if (!impl_->no_space.load()) return absl::OkStatus();
  const auto now = std::chrono::steady_clock::now();
  if (now - impl_->last_resume >= std::chrono::seconds(1)) {
    impl_->last_resume = now;
    // Resume clears RocksDB's background error once its recovery (a new
    // write-ahead log, a flush) succeeds, i.e. once space is back. RocksDB
    // resumes by itself only from background (flush, compaction) errors
    // and with an SstFileManager; a failed log write needs this call.
    rocksdb::Status s = impl_->db->Resume();
    if (s.ok()) {
      impl_->no_space = false;
      impl_->no_space_reason.clear();
      return absl::OkStatus();
    }
    // Busy: RocksDB's own recovery (SstFileManager) is under way; the
    // original reason still says more than "Resource busy".
    if (!s.IsBusy()) {
      impl_->no_space_reason =
          FromRocks(s, "cannot resume writes", impl_->dir).ToString();
    }
  }
  return absl::ResourceExhaustedError(absl::StrCat(
      "writes are refused until space is freed on the data directory's disk: ",
      impl_->no_space_reason));
}

uint64_t Storage::model_count() const { return impl_->model_count.load(); }

absl::Status Storage::CheckScanned(uint64_t scanned) const {
  const uint64_t recorded = impl_->model_count.load();
  if (scanned == recorded) return absl::OkStatus();
  return absl::DataLossError(absl::StrCat(
      "the models family holds ", scanned, " models but ", recorded,
      " were recorded with the acknowledged writes: models were lost from ",
      DescribeFiles(impl_->dir),
      "; refusing to serve a smaller database (see docs/recovery.md)"));
}

RocksHandles Storage::rocks() const {
  return {impl_->db.get(), impl_->meta, impl_->models, impl_->media};
}

const std::string& Storage::dir() const { return impl_->dir; }

absl::Status Storage::ReloadCounters() {
  std::lock_guard<std::mutex> lock(impl_->write_mu);
  absl::StatusOr<Counters> counters =
      ReadCounters(impl_->db.get(), impl_->meta, impl_->dir);
  if (!counters.ok()) return counters.status();
  impl_->last_seq = counters->last_seq;
  impl_->writes = counters->writes;
  impl_->model_count = counters->models.value_or(impl_->model_count.load());
  return impl_->ack->Record({impl_->writes.load(), impl_->model_count.load()});
}

int64_t Storage::DiskBytes() const {
  int64_t total = 0;
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(impl_->dir, ec);
       !ec && it != std::filesystem::recursive_directory_iterator();
       it.increment(ec)) {
    std::error_code size_ec;
    if (it->is_regular_file(size_ec)) {
      const auto size = it->file_size(size_ec);
      if (!size_ec) total += static_cast<int64_t>(size);
    }
  }
  return total;
}

EngineStats Storage::engine_stats() const {
  EngineStats stats;
  if (impl_->statistics) {
    stats.stall_micros =
        impl_->statistics->getTickerCount(rocksdb::STALL_MICROS);
    stats.wal_syncs =
        impl_->statistics->getTickerCount(rocksdb::WAL_FILE_SYNCED);
  }
  if (impl_->listener) {
    stats.delayed_stalls = impl_->listener->delayed.load();
    stats.stopped_stalls = impl_->listener->stopped.load();
  }
  for (rocksdb::ColumnFamilyHandle* family :
       {impl_->meta, impl_->models, impl_->media}) {
    if (family == nullptr) continue;
    uint64_t value = 0;
    if (impl_->db->GetIntProperty(family, "rocksdb.estimate-live-data-size",
                                  &value)) {
      stats.live_data_bytes += value;
    }
    if (impl_->db->GetIntProperty(family, "rocksdb.total-sst-files-size",
                                  &value)) {
      stats.sst_bytes += value;
    }
    if (impl_->db->GetIntProperty(family, "rocksdb.cur-size-all-mem-tables",
                                  &value)) {
      stats.memtable_bytes += value;
    }
  }
  return stats;
}

}  // namespace tpr::indexer
