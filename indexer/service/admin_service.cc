#include "indexer/service/admin_service.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/grpc_status.h"
#include "indexer/service/replication.h"

namespace tpr::indexer {
namespace {

namespace fs = std::filesystem;

// Checkpoint copies live in the data directory (same file system: hard
// links, no copy) under this prefix while they are streamed; RocksDB
// ignores directories it did not make.
constexpr char kCheckpointPrefix[] = ".checkpoint-";
constexpr size_t kChunkBytes = 1 << 20;
constexpr size_t kLogMessageBytes = 4 << 20;

bool SamePath(const std::string& a, const std::string& b) {
  std::error_code ec;
  return fs::weakly_canonical(a, ec) == fs::weakly_canonical(b, ec);
}

// OK when `path` (request field `field`) lies under `root` (see
// AdminOptions::backup_root); an empty path is left to the callee's own
// check.
absl::Status CheckUnderBackupRoot(const std::string& root, const char* field,
                                  const std::string& path) {
  if (root.empty()) {
    return absl::FailedPreconditionError(
        "backups and restores are off on this indexer: start it with "
        "--backup-root DIR, under which backup sets and restores go");
  }
  if (path.empty()) return absl::OkStatus();
  std::error_code ec;
  const fs::path resolved = fs::weakly_canonical(fs::absolute(path, ec), ec);
  const fs::path base = fs::weakly_canonical(fs::absolute(root, ec), ec);
  const fs::path relative = resolved.lexically_relative(base);
  if (ec || relative.empty() || *relative.begin() == "..") {
    return absl::InvalidArgumentError(
        absl::StrCat(field, " '", path, "' is outside the backup root '", root,
                     "' (--backup-root)"));
  }
  return absl::OkStatus();
}

}  // namespace

IndexerAdminService::IndexerAdminService(IndexerCore* core, Follower* follower,
                                         AdminOptions options)
    : core_(core), follower_(follower), options_(std::move(options)) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(core_->storage().dir(), ec)) {
    if (absl::StartsWith(entry.path().filename().string(), kCheckpointPrefix)) {
      fs::remove_all(entry.path(), ec);
    }
  }
}

grpc::Status IndexerAdminService::Backup(grpc::ServerContext*,
                                         const tpr::v1::BackupRequest* request,
                                         tpr::v1::BackupResponse* response) {
  if (absl::Status st = CheckUnderBackupRoot(options_.backup_root, "backup_dir",
                                             request->backup_dir());
      !st.ok()) {
    return common::ToGrpcStatus(st);
  }
  if (request->keep_last() < 0) {
    return common::ToGrpcStatus(absl::InvalidArgumentError(absl::StrCat(
        "keep_last is ", request->keep_last(), "; it must be >= 0")));
  }
  // The tree goes into the backup as it is now, so a restore loads it
  // instead of rebuilding.
  if (absl::Status st = core_->PersistTree(); !st.ok())
    return common::ToGrpcStatus(st);
  const int64_t models = static_cast<int64_t>(core_->storage().model_count());
  absl::StatusOr<BackupResult> backup = CreateBackup(
      core_->storage(), request->backup_dir(), request->keep_last());
  if (!backup.ok()) return common::ToGrpcStatus(backup.status());
  response->set_backup_id(backup->backup_id);
  response->set_size_bytes(backup->size_bytes);
  response->set_files(backup->files);
  response->set_copied_bytes(backup->copied_bytes);
  response->set_models(models);
  response->set_unix_seconds(backup->unix_seconds);
  response->set_verified(true);
  if (options_.log) {
    options_.log(absl::StrCat(
        "backup ", backup->backup_id, " verified: ", backup->files, " files, ",
        backup->size_bytes, " bytes (", backup->copied_bytes, " copied)"));
  }
  return grpc::Status::OK;
}

grpc::Status IndexerAdminService::Restore(
    grpc::ServerContext*, const tpr::v1::RestoreRequest* request,
    tpr::v1::RestoreResponse* response) {
  for (const auto& [field, path] : {std::pair<const char*, const std::string&>{
                                        "backup_dir", request->backup_dir()},
                                    {"data_dir", request->data_dir()}}) {
    if (absl::Status st =
            CheckUnderBackupRoot(options_.backup_root, field, path);
        !st.ok()) {
      return common::ToGrpcStatus(st);
    }
  }
  if (!request->data_dir().empty() &&
      SamePath(request->data_dir(), core_->storage().dir())) {
    return common::ToGrpcStatus(absl::FailedPreconditionError(
        "data_dir is this indexer's own data directory; restore into an empty "
        "directory and "
        "start an indexer on it"));
  }
  absl::StatusOr<RestoreResult> restored = RestoreBackup(
      request->backup_dir(), request->backup_id(), request->data_dir());
  if (!restored.ok()) return common::ToGrpcStatus(restored.status());
  // Counted by opening it as an indexer would (checks included).
  // create_if_missing: the database is there; ACKNOWLEDGED is made.
  StorageOptions storage_options;
  absl::StatusOr<std::unique_ptr<Storage>> storage =
      Storage::Open(request->data_dir(), storage_options);
  if (!storage.ok()) return common::ToGrpcStatus(storage.status());
  response->set_backup_id(restored->backup_id);
  response->set_models(static_cast<int64_t>((*storage)->model_count()));
  return grpc::Status::OK;
}

grpc::Status IndexerAdminService::Promote(grpc::ServerContext*,
                                          const tpr::v1::PromoteRequest*,
                                          tpr::v1::PromoteResponse* response) {
  if (follower_ == nullptr) return grpc::Status::OK;  // already a primary
  absl::StatusOr<tpr::v1::PromoteResponse> promoted = follower_->Promote();
  if (!promoted.ok()) return common::ToGrpcStatus(promoted.status());
  *response = std::move(*promoted);
  return grpc::Status::OK;
}

grpc::Status IndexerAdminService::ReplicationStatus(
    grpc::ServerContext*, const tpr::v1::ReplicationStatusRequest*,
    tpr::v1::ReplicationStatusResponse* response) {
  if (follower_ != nullptr) {
    *response = follower_->Status();
    return grpc::Status::OK;
  }
  response->set_role("primary");
  response->set_applied_sequence(LatestSequence(core_->storage()));
  absl::StatusOr<std::string> identity = DatabaseIdentity(core_->storage());
  if (!identity.ok()) return common::ToGrpcStatus(identity.status());
  response->set_db_identity(*identity);
  return grpc::Status::OK;
}

grpc::Status IndexerAdminService::Checkpoint(
    grpc::ServerContext* context, const tpr::v1::CheckpointRequest*,
    grpc::ServerWriter<tpr::v1::CheckpointChunk>* writer) {
  if (!core_->following().empty()) {
    return common::ToGrpcStatus(absl::FailedPreconditionError(
        absl::StrCat("this indexer is a follower of ", core_->following(),
                     "; follow the primary")));
  }
  const std::string dir =
      absl::StrCat(core_->storage().dir(), "/", kCheckpointPrefix, getpid(),
                   "-", ++checkpoints_);
  absl::StatusOr<uint64_t> sequence = CreateCheckpoint(core_->storage(), dir);
  struct Cleanup {
    std::string dir;
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cleanup{dir};
  if (!sequence.ok()) return common::ToGrpcStatus(sequence.status());
  std::vector<std::string> files;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (entry.is_regular_file())
      files.push_back(entry.path().filename().string());
  }
  std::sort(files.begin(), files.end());
  std::string buffer(kChunkBytes, '\0');
  uint64_t bytes = 0;
  for (const std::string& name : files) {
    std::FILE* f = std::fopen((dir + "/" + name).c_str(), "rb");
    if (f == nullptr) {
      return common::ToGrpcStatus(absl::InternalError(
          absl::StrCat("cannot read checkpoint file ", name)));
    }
    uint64_t offset = 0;
    bool first = true;
    for (;;) {
      const size_t n = std::fread(buffer.data(), 1, buffer.size(), f);
      if (n == 0 && !first) break;
      tpr::v1::CheckpointChunk chunk;
      chunk.set_file(name);
      chunk.set_offset(offset);
      chunk.set_data(buffer.data(), n);
      if (context->IsCancelled() || !writer->Write(chunk)) {
        std::fclose(f);
        return grpc::Status(grpc::StatusCode::CANCELLED, "follower went away");
      }
      offset += n;
      bytes += n;
      first = false;
      if (n < buffer.size()) break;
    }
    const bool failed = std::ferror(f) != 0;
    std::fclose(f);
    if (failed) {
      return common::ToGrpcStatus(absl::InternalError(
          absl::StrCat("cannot read checkpoint file ", name)));
    }
  }
  absl::StatusOr<std::string> identity = DatabaseIdentity(core_->storage());
  if (!identity.ok()) return common::ToGrpcStatus(identity.status());
  tpr::v1::CheckpointChunk last;
  last.set_sequence(*sequence);
  last.set_done(true);
  last.set_db_identity(*identity);
  writer->Write(last);
  if (options_.log) {
    options_.log(absl::StrCat("sent a checkpoint at sequence ", *sequence, ": ",
                              files.size(), " files, ", bytes, " bytes"));
  }
  return grpc::Status::OK;
}

grpc::Status IndexerAdminService::TailLog(
    grpc::ServerContext* context, const tpr::v1::TailLogRequest* request,
    grpc::ServerWriter<tpr::v1::LogBatch>* writer) {
  if (!core_->following().empty()) {
    return common::ToGrpcStatus(absl::FailedPreconditionError(
        absl::StrCat("this indexer is a follower of ", core_->following(),
                     "; follow the primary")));
  }
  Storage& storage = core_->storage();
  if (!request->db_identity().empty()) {
    absl::StatusOr<std::string> identity = DatabaseIdentity(storage);
    if (!identity.ok()) return common::ToGrpcStatus(identity.status());
    if (*identity != request->db_identity()) {
      return common::ToGrpcStatus(absl::FailedPreconditionError(absl::StrCat(
          "this primary is database ", *identity,
          " but the follower copied database ", request->db_identity(),
          " (the primary was restored or replaced, or the follower points at "
          "the wrong "
          "indexer); refusing to send another database's log: start the "
          "follower again from "
          "an empty directory")));
    }
  }
  uint64_t from = std::max<uint64_t>(request->from_sequence(), 1);
  {
    const uint64_t latest = LatestSequence(storage);
    if (from > latest + 1) {
      return common::ToGrpcStatus(absl::FailedPreconditionError(
          absl::StrCat("the follower asks for sequence ", from,
                       " but this primary's latest is ", latest,
                       ": it is not this database's follower, or this primary "
                       "lost writes; start the "
                       "follower from an empty directory")));
    }
  }
  // One cursor for the whole stream: each poll reads only the new log.
  LogCursor cursor(storage, from);
  auto last_sent = std::chrono::steady_clock::now();
  while (!stopping_ && !context->IsCancelled()) {
    const uint64_t latest = LatestSequence(storage);
    if (from <= latest) {
      absl::StatusOr<std::vector<LoggedBatch>> batches =
          cursor.Read(kLogMessageBytes);
      if (!batches.ok()) return common::ToGrpcStatus(batches.status());
      for (LoggedBatch& b : *batches) {
        tpr::v1::LogBatch message;
        message.set_sequence(b.sequence);
        *message.mutable_batch() = std::move(b.data);
        from = b.sequence + b.count;
        // What the primary had when it looked: the follower is caught up
        // once it has applied that much.
        message.set_primary_sequence(std::max(latest, from - 1));
        if (!writer->Write(message)) return grpc::Status::OK;  // follower gone
      }
      if (!batches->empty()) {
        last_sent = std::chrono::steady_clock::now();
        continue;
      }
    } else if (std::chrono::steady_clock::now() - last_sent >=
               std::chrono::milliseconds(options_.heartbeat_ms)) {
      tpr::v1::LogBatch heartbeat;
      heartbeat.set_primary_sequence(latest);
      if (!writer->Write(heartbeat)) return grpc::Status::OK;
      last_sent = std::chrono::steady_clock::now();
    }
    std::this_thread::sleep_for(
        std::chrono::milliseconds(options_.tail_poll_ms));
  }
  return grpc::Status::OK;
}

}  // namespace tpr::indexer
