// IndexerCore's follower side (indexer_core.h): applying the primary's
// replicated writes, refusing local writes while following, promotion.
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/status_macros.h"
#include "indexer/service/convert.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/replication.h"

namespace tpr::indexer {

std::string IndexerCore::following() const {
  tpr::common::MutexLock lock(&follow_mu_);
  return follow_;
}

absl::Status IndexerCore::CheckWritable() const {
  tpr::common::MutexLock lock(&follow_mu_);
  if (follow_.empty()) return absl::OkStatus();
  return absl::FailedPreconditionError(absl::StrCat(
      "this indexer is a read-only follower of ", follow_,
      "; send writes to the primary (or promote this follower: tpr promote)"));
}

absl::StatusOr<uint64_t> IndexerCore::ApplyReplicated(const std::string& data,
                                                      uint64_t sequence) {
  tpr::common::MutexLock lock(&write_mu_);
  if (following().empty()) {
    return absl::FailedPreconditionError(
        "not a follower (promoted): replication stopped");
  }
  TPR_ASSIGN_OR_RETURN(AppliedBatch applied,
                       ApplyLoggedBatch(*storage_, data, sequence));
  if (applied.changes.empty()) return applied.last_sequence;
  // Durable from here on; the in-memory views follow, as in WriteGroup,
  // under one view lock (a search sees the batch whole or not at all). A
  // batch is atomic, so only each id's last change matters.
  std::unordered_map<std::string, size_t> last;
  for (size_t i = 0; i < applied.changes.size(); ++i)
    last[applied.changes[i].id] = i;
  std::vector<std::pair<std::string, tpr::index::Signature>> entries;
  std::vector<std::string> removed;
  std::vector<std::string> outdated;
  std::vector<LabelChange> labels;
  std::vector<std::pair<std::string, ModelInfo>> infos;
  for (size_t i = 0; i < applied.changes.size(); ++i) {
    const ReplicatedChange& change = applied.changes[i];
    if (last[change.id] != i) continue;
    if (!change.model.has_value()) {
      removed.push_back(change.id);
      labels.emplace_back(change.id, std::nullopt);
      continue;
    }
    const tpr::v1::Model& model = *change.model;
    absl::StatusOr<tpr::index::Signature> sig =
        ToIndexSignature(model.signature());
    if (absl::IsFailedPrecondition(sig.status())) {
      // Another signature version: kept and listed, not indexed (as Open).
      outdated.push_back(change.id);
      removed.push_back(change.id);
    } else if (!sig.ok()) {
      return absl::DataLossError(absl::StrCat("replicated model '", change.id,
                                              "': ", sig.status().message()));
    } else {
      entries.emplace_back(change.id, std::move(*sig));
    }
    labels.emplace_back(change.id, model.label());
    infos.push_back({change.id, {model.label(), model.added_unix_micros()}});
  }
  {
    tpr::common::MutexLock view(&view_mu_);
    for (const std::string& id : removed) {
      index_->Remove(id);
      outdated_.erase(id);
    }
    absl::Status st = index_->UpsertBatch(entries);
    if (!st.ok()) {
      return absl::InternalError(
          absl::StrCat("index rejected a replicated model: ", st.message()));
    }
    for (const auto& entry : entries) outdated_.erase(entry.first);
    for (const std::string& id : outdated) outdated_.insert(id);
    labels_.Apply(labels);
  }
  for (const auto& change : labels) {
    if (!change.second.has_value()) table_.Erase(change.first);
  }
  table_.Put(infos);
  persister_->NoteWrites(applied.changes.size());
  return applied.last_sequence;
}

absl::StatusOr<std::string> IndexerCore::Promote() {
  tpr::common::MutexLock lock(&write_mu_);
  const std::string former = following();
  if (former.empty()) return former;
  TPR_RETURN_IF_ERROR(ClearAppliedSequence(*storage_));
  tpr::common::MutexLock follow(&follow_mu_);
  follow_.clear();
  return former;
}

}  // namespace tpr::indexer
