#include "indexer/service/storage.h"

#include <atomic>
#include <cstring>
#include <filesystem>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "rocksdb/db.h"
#include "rocksdb/options.h"
#include "rocksdb/table.h"
#include "rocksdb/write_batch.h"

namespace tpr::indexer {
namespace {

constexpr char kModelsFamily[] = "models";
constexpr char kTreeKey[] = "tree";
constexpr char kTreeSeqKey[] = "tree_seq";
constexpr char kLastSeqKey[] = "last_seq";

std::string EncodeSeq(uint64_t seq) {
  std::string out(8, '\0');
  for (int i = 0; i < 8; ++i) out[i] = static_cast<char>((seq >> (8 * i)) & 0xff);
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
// what failed and RocksDB's reason, which is about the files, not the caller.
absl::Status FromRocks(const rocksdb::Status& s, absl::string_view what) {
  if (s.ok()) return absl::OkStatus();
  const std::string message = absl::StrCat(what, ": ", s.ToString());
  if (s.IsCorruption()) return absl::DataLossError(message);
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
  if (!out.second.ParseFromArray(value.data() + 8, static_cast<int>(value.size() - 8))) {
    return absl::DataLossError(
        absl::StrCat("stored model '", key.ToString(), "' does not parse"));
  }
  return out;
}

}  // namespace

struct Storage::Impl {
  std::string dir;
  StorageOptions options;
  std::unique_ptr<rocksdb::DB> db;
  rocksdb::ColumnFamilyHandle* meta = nullptr;    // "default"
  rocksdb::ColumnFamilyHandle* models = nullptr;  // "models"
  // Sequence numbers are assigned under this mutex so that the order of
  // numbers equals the order of the RocksDB writes that carry them.
  std::mutex write_mu;
  std::atomic<uint64_t> last_seq{0};

  ~Impl() {
    if (db) {
      // A graceful close flushes the memtables, so that the next open has no
      // write-ahead log to replay (replaying up to a 64 MB memtable of
      // signatures, and flushing it again, was a visible part of reopen).
      // After a crash the log is replayed as usual.
      std::vector<rocksdb::ColumnFamilyHandle*> families;
      if (meta) families.push_back(meta);
      if (models) families.push_back(models);
      if (!families.empty()) {
        db->Flush(rocksdb::FlushOptions(), families).PermitUncheckedError();
      }
      if (meta) db->DestroyColumnFamilyHandle(meta);
      if (models) db->DestroyColumnFamilyHandle(models);
      db->Close().PermitUncheckedError();
    }
  }

  rocksdb::WriteOptions WriteOpts() const {
    rocksdb::WriteOptions w;
    w.sync = options.sync_writes;
    return w;
  }
};

Storage::Storage(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Storage::~Storage() = default;

absl::StatusOr<std::unique_ptr<Storage>> Storage::Open(const std::string& dir,
                                                       const StorageOptions& options) {
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

  rocksdb::Options db_options;
  db_options.create_if_missing = options.create_if_missing;
  db_options.create_missing_column_families = true;
  // Two cores shared with the search threads: one flush, one compaction.
  db_options.IncreaseParallelism(2);
  // Signatures are ~15 KB of doubles that barely compress; a larger write
  // buffer means fewer flushes during bulk ingest.
  rocksdb::ColumnFamilyOptions models_options;
  models_options.write_buffer_size = 64 << 20;
  models_options.compression = rocksdb::kNoCompression;
  rocksdb::BlockBasedTableOptions table;
  table.block_size = 32 << 10;
  models_options.table_factory.reset(rocksdb::NewBlockBasedTableFactory(table));
  rocksdb::ColumnFamilyOptions meta_options;
  meta_options.compression = rocksdb::kNoCompression;

  std::vector<rocksdb::ColumnFamilyDescriptor> families = {
      {rocksdb::kDefaultColumnFamilyName, meta_options},
      {kModelsFamily, models_options}};
  std::vector<rocksdb::ColumnFamilyHandle*> handles;
  rocksdb::DB* raw = nullptr;
  rocksdb::Status s = rocksdb::DB::Open(db_options, dir, families, &handles, &raw);
  if (!s.ok()) return FromRocks(s, "cannot open the model database");
  impl->db.reset(raw);
  impl->meta = handles[0];
  impl->models = handles[1];

  // The next sequence number continues after everything on disk: every
  // model write records the last number it used in the same atomic batch, so
  // no scan is needed (the tree marker is never above it).
  uint64_t last = 0;
  std::string value;
  s = impl->db->Get(rocksdb::ReadOptions(), impl->meta, kLastSeqKey, &value);
  if (s.ok() && value.size() == 8) {
    last = DecodeSeq(value.data());
  } else if (!s.ok() && !s.IsNotFound()) {
    return FromRocks(s, "cannot read the sequence counter");
  }
  impl->last_seq = last;
  return std::unique_ptr<Storage>(new Storage(std::move(impl)));
}

absl::Status Storage::Write(const std::vector<ModelWrite>& writes) {
  if (writes.empty()) return absl::OkStatus();
  std::lock_guard<std::mutex> lock(impl_->write_mu);
  uint64_t seq = impl_->last_seq.load();
  rocksdb::WriteBatch batch;
  std::string value;
  for (const ModelWrite& w : writes) {
    if (w.model == nullptr) {
      batch.Delete(impl_->models, w.id);
      continue;
    }
    value = EncodeSeq(++seq);
    if (!w.model->AppendToString(&value)) {
      return absl::InternalError(absl::StrCat("cannot serialize model '", w.id, "'"));
    }
    batch.Put(impl_->models, w.id, value);
  }
  batch.Put(impl_->meta, kLastSeqKey, EncodeSeq(seq));
  rocksdb::Status s = impl_->db->Write(impl_->WriteOpts(), &batch);
  if (!s.ok()) return FromRocks(s, "cannot write models");
  impl_->last_seq = seq;
  return absl::OkStatus();
}

absl::StatusOr<tpr::v1::Model> Storage::GetModel(const std::string& id) const {
  rocksdb::PinnableSlice value;
  rocksdb::Status s =
      impl_->db->Get(rocksdb::ReadOptions(), impl_->models, id, &value);
  if (s.IsNotFound()) return absl::NotFoundError(absl::StrCat("no model with id '", id, "'"));
  if (!s.ok()) return FromRocks(s, "cannot read a model");
  auto decoded = DecodeModel(value, id);
  if (!decoded.ok()) return decoded.status();
  return std::move(decoded->second);
}

absl::Status Storage::ForEachModel(
    const std::function<absl::Status(uint64_t, tpr::v1::Model&&)>& fn,
    int threads) const {
  rocksdb::ReadOptions read;
  // A full scan should not evict hot blocks; it reads each block once.
  read.fill_cache = false;
  read.readahead_size = 2 << 20;
  std::unique_ptr<rocksdb::Iterator> it(impl_->db->NewIterator(read, impl_->models));
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
  std::mutex mu;
  std::condition_variable ready;  // a chunk was queued, or the scan ended
  std::condition_variable room;   // a chunk was taken
  std::deque<Chunk> queue;
  bool scan_done = false;
  absl::Status first_error;  // guarded by mu
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
        absl::Status st = decoded.ok() ? fn(decoded->first, std::move(decoded->second))
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
  return FromRocks(impl_->db->Write(w, &batch), "cannot persist the VP-tree");
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
  if (seq.size() != 8) return absl::DataLossError("VP-tree marker is malformed");
  tree.seq = DecodeSeq(seq.data());
  return tree;
}

uint64_t Storage::last_seq() const { return impl_->last_seq.load(); }

int64_t Storage::DiskBytes() const {
  int64_t total = 0;
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(impl_->dir, ec);
       !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
    std::error_code size_ec;
    if (it->is_regular_file(size_ec)) {
      const auto size = it->file_size(size_ec);
      if (!size_ec) total += static_cast<int64_t>(size);
    }
  }
  return total;
}

}  // namespace tpr::indexer
