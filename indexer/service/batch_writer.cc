#include "indexer/service/batch_writer.h"

#include <utility>

#include "common/status_macros.h"
#include "indexer/service/indexer_core.h"

namespace tpr::indexer {

BatchWriter::~BatchWriter() {
  Wait().IgnoreError();
  {
    tpr::common::MutexLock lock(&mu_);
    stopping_ = true;
  }
  if (worker_.joinable()) worker_.join();
}

absl::Status BatchWriter::Add(tpr::v1::UpsertRequest request) {
  tpr::index::Signature signature;
  absl::Status valid = core_->CheckModel(request.model(), &signature);
  if (!valid.ok()) {
    // Keep the promise "models before the failing one are kept".
    TPR_RETURN_IF_ERROR(FlushAsync());
    TPR_RETURN_IF_ERROR(Wait());
    return valid;
  }
  pending_.requests.push_back(std::move(request));
  pending_.signatures.push_back(std::move(signature));
  if (pending_.requests.size() >= core_->batch_group()) return FlushAsync();
  return absl::OkStatus();
}

absl::Status BatchWriter::Wait() {
  tpr::common::MutexLock lock(&mu_);
  mu_.Await([this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) { return !busy_; });
  return error_;
}

absl::Status BatchWriter::FlushAsync() {
  TPR_RETURN_IF_ERROR(Wait());
  if (pending_.requests.empty()) return absl::OkStatus();
  tpr::common::MutexLock lock(&mu_);
  handed_ = std::move(pending_);
  pending_ = Group();
  busy_ = true;
  if (!worker_.joinable()) worker_ = std::thread([this] { WorkerLoop(); });
  return absl::OkStatus();
}

void BatchWriter::WriteGroup(Group group) {
  absl::StatusOr<std::vector<WriteOutcome>> outcome =
      core_->WriteGroup(group.requests, group.signatures);
  tpr::common::MutexLock lock(&mu_);
  if (!outcome.ok()) {
    error_ = outcome.status();
    return;
  }
  for (WriteOutcome o : *outcome) {
    if (o == WriteOutcome::kSkipped) {
      counts_.set_skipped(counts_.skipped() + 1);
    } else {
      counts_.set_written(counts_.written() + 1);
    }
  }
}

void BatchWriter::WorkerLoop() {
  tpr::common::MutexLock lock(&mu_);
  while (true) {
    mu_.Await([this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
      return handed_.has_value() || stopping_;
    });
    if (!handed_.has_value()) return;  // stopping, nothing left
    Group group = std::move(*handed_);
    handed_.reset();
    mu_.Unlock();
    WriteGroup(std::move(group));
    mu_.Lock();
    busy_ = false;
  }
}

absl::StatusOr<tpr::v1::BatchUpsertResponse> BatchWriter::Finish() {
  TPR_RETURN_IF_ERROR(Wait());
  if (!pending_.requests.empty()) {
    // The last group is written on this thread: nothing follows it to
    // overlap with, and a stream of one group then needs no worker at all.
    Group group = std::move(pending_);
    pending_ = Group();
    WriteGroup(std::move(group));
  }
  tpr::common::MutexLock lock(&mu_);
  if (!error_.ok()) return error_;
  return counts_;
}

}  // namespace tpr::indexer
