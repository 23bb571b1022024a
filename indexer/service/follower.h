// Follower mode of tpr-indexer (`--follow PRIMARY`): a read-only
// copy of one primary, kept current by RocksDB's own mechanisms.
//
//   1. PrepareFollowerDir, before the store is opened: an empty data
//      directory receives a consistent copy of the primary (RocksDB
//      Checkpoint, streamed over IndexerAdmin.Checkpoint), models and the
//      persisted VP-tree, and records the primary sequence it reflects.
//   2. Follower::Start, once the core is open: tails the primary's
//      write-ahead log (IndexerAdmin.TailLog, RocksDB GetUpdatesSince) and
//      applies each batch to the store, atomically with the new applied
//      sequence, then to the in-memory index (IndexerCore::ApplyReplicated).
//      Readiness is NOT_SERVING until it has applied everything the primary
//      had when it last looked; afterwards it stays ready (a follower cut off
//      from its primary keeps serving what it has: ReplicationStatus shows
//      how long it has not heard from it).
//   3. After kill -9 the store is consistent (applied sequence and data in
//      one write), so a restart resumes tailing where it stopped.
//   4. When the primary no longer keeps the log the follower needs
//      (OUT_OF_RANGE), the follower marks its directory for a fresh copy and
//      asks its process to restart (on_resync); step 1 then copies again.
//   5. Promote: stops tailing, removes the follower marks, and the indexer
//      accepts writes. Nothing else changes roles: there is no election.
//   6. Identity: the copy records the primary's database identity
//      (replication.h DatabaseIdentity) and sends it with every TailLog; a
//      primary that is another database (restored from a backup, replaced,
//      or the wrong address) refuses with FAILED_PRECONDITION, and the
//      follower then applies nothing, reports NOT_SERVING with the reason
//      (Readiness, ReplicationStatus.error) and asks again every
//      retry_max_ms, never wiping its copy by itself. The copy itself gets
//      an identity of its own, so a promoted follower is a new database to
//      the followers of its former primary.
//
// The data directory holds a marker file FOLLOWER ("primary ADDR", "state
// copying|ready|resync") while it is a follower's. --follow refuses a
// non-empty directory without it (a primary's data is never wiped); a
// directory in state copying or resync is emptied and copied again.
#ifndef TPR_INDEXER_SERVICE_FOLLOWER_H_
#define TPR_INDEXER_SERVICE_FOLLOWER_H_

#include <grpcpp/client_context.h>
#include <grpcpp/security/credentials.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "indexer/service/indexer_core.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::indexer {

// FollowerOptions: whom to follow and how.
struct FollowerOptions {
  // HOST:PORT of the primary tpr-indexer. Required.
  std::string primary;
  // Channel credentials for the primary: TLS as the other clients make them
  // (tpr::client::MakeChannelCredentials from tpr-indexer's --follow-tls*
  // flags). nullptr: plaintext. Default nullptr.
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  // Name the primary's certificate carries when not the host in `primary`
  // (--follow-tls-server-name). Empty: the host. Only with TLS credentials.
  std::string tls_server_name;
  // The follower's data directory. Required.
  std::string data_dir;
  // API key sent to the primary (admin role) when it checks keys; empty:
  // none.
  std::string api_key;
  // Receives one line per notable event. Default: none.
  std::function<void(const std::string&)> log;
  // Waits between reconnection attempts, doubling from the first to the
  // last, in milliseconds. Defaults 100 and 2000.
  int retry_min_ms = 100;
  int retry_max_ms = 2000;
};

// kFollowerMarker is the marker file's name inside the data directory.
inline constexpr char kFollowerMarker[] = "FOLLOWER";

// PrepareFollowerDir makes options.data_dir ready to open as a follower:
// resumes a follower's directory, or fetches a checkpoint from the primary
// into an empty (or absent) one, or into one marked for a fresh copy after
// emptying it. Retries an unreachable primary until it answers (logging
// each failure). Returns FAILED_PRECONDITION for a non-empty directory that
// is not a follower's (naming it), the primary's errors other than
// UNAVAILABLE, and I/O errors. Cost: the copy's size over the network.
absl::Status PrepareFollowerDir(const FollowerOptions& options);

// Follower: the tailing thread of a follower. Thread-safe.
class Follower {
 public:
  // `core` must be open on options.data_dir with CoreOptions::follow set,
  // and outlive the Follower.
  Follower(IndexerCore* core, FollowerOptions options);
  // The destructor calls Stop().
  ~Follower();
  Follower(const Follower&) = delete;
  Follower& operator=(const Follower&) = delete;

  // Start starts tailing on a background thread. `on_resync` is called
  // (once, from that thread) when the follower has fallen behind the
  // primary's kept log and marked its directory for a fresh copy: the
  // process should then stop and start again. Call once.
  void Start(std::function<void()> on_resync);

  // Stop ends tailing (cancels the stream) and joins the thread.
  // Idempotent.
  void Stop();

  // Readiness is the server's readiness check: "" once caught up, else
  // why not (catching up, or the primary refuses to be tailed).
  std::string Readiness() const;

  // Status reports role, sequences and lag (ReplicationStatusResponse).
  tpr::v1::ReplicationStatusResponse Status() const;

  // Promote stops tailing, promotes the core (IndexerCore::Promote) and
  // removes the marker file. Returns the former primary and the last
  // applied sequence. Errors: the store's. Idempotent.
  absl::StatusOr<tpr::v1::PromoteResponse> Promote();

 private:
  void Run(std::function<void()> on_resync);

  IndexerCore* const core_;
  const FollowerOptions options_;
  std::unique_ptr<tpr::v1::IndexerAdmin::Stub> stub_;
  std::atomic<uint64_t> applied_{0};
  std::atomic<uint64_t> primary_seq_{0};
  std::atomic<bool> caught_up_{false};
  std::atomic<bool> promoted_{false};
  std::atomic<int64_t> last_heard_ms_{-1};  // steady clock, ms; -1: never

  // The primary database's identity this copy follows ("" when unknown),
  // and why the primary refuses to be tailed ("" when it does not).
  mutable absl::Mutex state_mu_;
  std::string primary_identity_ ABSL_GUARDED_BY(state_mu_);
  std::string refused_ ABSL_GUARDED_BY(state_mu_);

  absl::Mutex mu_;
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  grpc::ClientContext* context_ ABSL_GUARDED_BY(mu_) = nullptr;
  std::thread thread_;
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_FOLLOWER_H_
