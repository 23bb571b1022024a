// IndexerAdminService: the tpr.v1.IndexerAdmin gRPC service of one
// tpr-indexer (indexer.proto): backups and restores (replication.h),
// promotion and replication status of a follower (follower.h), and the
// primary's side of replication: Checkpoint streams a consistent copy,
// TailLog streams the write-ahead log. Every method needs the admin role
// when API keys are on. Served next to IndexerService by tpr-indexer.
//
//   IndexerAdminService admin(core, follower /*nullable*/, {.log = log});
//   StartServer(options, {&service, &admin});  ...  admin.Stop();
#ifndef TPR_INDEXER_SERVICE_ADMIN_SERVICE_H_
#define TPR_INDEXER_SERVICE_ADMIN_SERVICE_H_

#include <atomic>
#include <functional>
#include <string>

#include "indexer/service/follower.h"
#include "indexer/service/indexer_core.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::indexer {

// AdminOptions: how the admin service behaves.
struct AdminOptions {
  // How often TailLog looks for new writes while the follower is caught
  // up, in milliseconds. Default 5.
  int tail_poll_ms = 5;
  // Heartbeat interval of an idle TailLog stream, in milliseconds. Default
  // 500.
  int heartbeat_ms = 500;
  // Receives one line per notable event. Default: none.
  std::function<void(const std::string&)> log;
  // The directory every backup set (BackupRequest.backup_dir,
  // RestoreRequest.backup_dir) and restore target (RestoreRequest.data_dir)
  // must lie under, after resolving symbolic links and "..": a path
  // outside it is INVALID_ARGUMENT naming the field and the path. Empty:
  // Backup and Restore are FAILED_PRECONDITION (tpr-indexer
  // --backup-root). Default empty.
  std::string backup_root;
};

// IndexerAdminService: see the file comment. Thread-safe. `core` (and
// `follower`, when not null) must outlive it.
class IndexerAdminService final : public tpr::v1::IndexerAdmin::Service {
 public:
  // Removes checkpoint copies a crashed process left in the data directory.
  IndexerAdminService(IndexerCore* core, Follower* follower,
                      AdminOptions options);

  grpc::Status Backup(grpc::ServerContext* context,
                      const tpr::v1::BackupRequest* request,
                      tpr::v1::BackupResponse* response) override;
  grpc::Status Restore(grpc::ServerContext* context,
                       const tpr::v1::RestoreRequest* request,
                       tpr::v1::RestoreResponse* response) override;
  grpc::Status Promote(grpc::ServerContext* context,
                       const tpr::v1::PromoteRequest* request,
                       tpr::v1::PromoteResponse* response) override;
  grpc::Status ReplicationStatus(
      grpc::ServerContext* context,
      const tpr::v1::ReplicationStatusRequest* request,
      tpr::v1::ReplicationStatusResponse* response) override;
  grpc::Status Checkpoint(
      grpc::ServerContext* context, const tpr::v1::CheckpointRequest* request,
      grpc::ServerWriter<tpr::v1::CheckpointChunk>* writer) override;
  grpc::Status TailLog(grpc::ServerContext* context,
                       const tpr::v1::TailLogRequest* request,
                       grpc::ServerWriter<tpr::v1::LogBatch>* writer) override;

  // Stop ends every TailLog stream (they never end by themselves), so a
  // graceful shutdown does not wait out its grace period for them. Call
  // before shutting the server down. Idempotent.
  void Stop() { stopping_ = true; }

 private:
  IndexerCore* const core_;
  Follower* const follower_;
  const AdminOptions options_;
  std::atomic<bool> stopping_{false};
  std::atomic<uint64_t> checkpoints_{0};
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_ADMIN_SERVICE_H_
