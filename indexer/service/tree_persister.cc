#include "indexer/service/tree_persister.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/time/time.h"
#include "common/status_macros.h"

namespace tpr::indexer {

TreePersister::TreePersister(Storage* storage,
                             const tpr::index::SignatureIndex* index,
                             TreePersisterOptions options)
    : storage_(storage), index_(index), options_(std::move(options)) {}

TreePersister::~TreePersister() { Stop(); }

void TreePersister::MarkSaved(const std::string& bytes) {
  tpr::common::MutexLock lock(&save_mu_);
  saved_hash_ = std::hash<std::string>()(bytes);
  saved_indexed_ = index_->indexed();
  saved_buffered_ = index_->buffered();
}

void TreePersister::Start() {
  if (options_.interval_ms > 0) thread_ = std::thread([this] { Loop(); });
}

void TreePersister::Loop() {
  tpr::common::MutexLock lock(&stop_mu_);
  while (!stopping_) {
    // Sleeps for the interval unless Stop() sets stopping_.
    stop_mu_.AwaitWithTimeout(
        [this]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(stop_mu_) { return stopping_; },
        absl::Milliseconds(options_.interval_ms));
    if (stopping_) break;
    stop_mu_.Unlock();
    absl::Status st = PersistNow();
    if (!st.ok() && options_.log) {
      options_.log(absl::StrCat("cannot persist the VP-tree: ", st.ToString()));
    }
    stop_mu_.Lock();
  }
}

absl::Status TreePersister::PersistNow() {
  tpr::common::MutexLock lock(&save_mu_);
  const size_t indexed = index_->indexed();
  const size_t buffered = index_->buffered();
  // The tree only changes with a rebuild, which shows in these counts or
  // follows writes; without either there is nothing new to save.
  if (writes_since_save_.load() == 0 && indexed == saved_indexed_ &&
      buffered == saved_buffered_) {
    return absl::OkStatus();
  }
  writes_since_save_ = 0;
  // The marker is read before serializing (see Storage::SaveTree).
  const uint64_t seq = storage_->last_seq();
  const std::string bytes = index_->SerializeTree();
  const size_t hash = std::hash<std::string>()(bytes);
  saved_indexed_ = indexed;
  saved_buffered_ = buffered;
  if (hash == saved_hash_) return absl::OkStatus();
  TPR_RETURN_IF_ERROR(storage_->SaveTree(bytes, seq));
  saved_hash_ = hash;
  if (options_.log) {
    options_.log(absl::StrCat("persisted the VP-tree: ", indexed, " models, ",
                              bytes.size(), " bytes"));
  }
  return absl::OkStatus();
}

void TreePersister::Stop() {
  {
    tpr::common::MutexLock lock(&stop_mu_);
    if (stopped_) return;
    stopped_ = true;
    stopping_ = true;
  }
  if (thread_.joinable()) thread_.join();
  absl::Status st = PersistNow();
  if (!st.ok() && options_.log) {
    options_.log(
        absl::StrCat("cannot persist the VP-tree at close: ", st.ToString()));
  }
}

}  // namespace tpr::indexer
