// BatchWriter: the write path of a BatchUpsert stream. It groups the
// stream's upserts into synced writes of CoreOptions::batch_group models
// (group commit: one fsync per group instead of per model) and overlaps each
// group's fsync with receiving and validating the next one.
//
//   BatchWriter batch(core);
//   while (reader->Read(&request)) {
//     TPR_RETURN_IF_ERROR(batch.Add(std::move(request)));
//   }
//   absl::StatusOr<tpr::v1::BatchUpsertResponse> counts = batch.Finish();
#ifndef TPR_INDEXER_SERVICE_BATCH_WRITER_H_
#define TPR_INDEXER_SERVICE_BATCH_WRITER_H_

#include <optional>
#include <thread>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "common/mutex.h"
#include "indexer/lib/signature.h"
#include "tpr/v1/indexer.pb.h"

namespace tpr::indexer {

class IndexerCore;

// BatchWriter: see the file comment. Add() validates a request and queues
// it; a full group is handed to the writer's worker thread, so the next
// group is received and validated while the previous one is synced (at most
// one group in flight). Finish() writes the rest and waits: every model
// counted in its answer is durable and indexed when it returns OK. On an
// error, everything queued before the failing request is written first (so
// models before it are kept), then the error is returned; a failed group
// write is reported by the next Add() or Finish(), and no later group is
// written.
//
// Threads: one worker per BatchWriter, started by its second group (a
// stream of one group is written on the caller's thread). It exists for the
// overlap: without it the stream stalled for every group's fsync, and the
// bench_service ingest measured with it (commit 320b5a0) is the reason.
//
// Not thread-safe itself (one stream); many BatchWriters may run at once,
// their groups serialized by IndexerCore's writer lock. The destructor waits
// for the group in flight. `core` must outlive it.
class BatchWriter {
 public:
  explicit BatchWriter(IndexerCore* core) : core_(core) {}
  ~BatchWriter();
  BatchWriter(const BatchWriter&) = delete;
  BatchWriter& operator=(const BatchWriter&) = delete;

  // Add queues one request. Errors as for IndexerCore::Upsert, except that
  // an existing id without overwrite is skipped (counted), not an error.
  // Cost: O(request size), plus waiting for the group in flight when a group
  // fills.
  absl::Status Add(tpr::v1::UpsertRequest request);

  // Finish writes what is queued, waits, and returns the counts.
  absl::StatusOr<tpr::v1::BatchUpsertResponse> Finish();

 private:
  struct Group {
    std::vector<tpr::v1::UpsertRequest> requests;
    std::vector<tpr::index::Signature> signatures;
  };
  // Hands the queued group to the worker once the group in flight is done;
  // returns that earlier group's error.
  absl::Status FlushAsync();
  // Waits for the group in flight; returns the first write error.
  absl::Status Wait();
  // Writes `group` and records its counts or error.
  void WriteGroup(Group group);
  void WorkerLoop();

  IndexerCore* const core_;
  Group pending_;  // the caller's thread only

  tpr::common::Mutex mu_;
  std::optional<Group> handed_ ABSL_GUARDED_BY(mu_);  // waiting for the worker
  bool busy_ ABSL_GUARDED_BY(mu_) = false;  // a group handed, not yet written
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  absl::Status error_ ABSL_GUARDED_BY(mu_);
  tpr::v1::BatchUpsertResponse counts_ ABSL_GUARDED_BY(mu_);
  std::thread worker_;
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_BATCH_WRITER_H_
