#include "indexer/service/shard_place.h"

#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "rocksdb/db.h"
#include "rocksdb/options.h"

namespace tpr::indexer {
namespace {

constexpr char kShardPlaceKey[] = "shard_place";

// Whether `place` is "I/N" with 0 <= I < N.
bool WellFormed(absl::string_view place) {
  std::vector<absl::string_view> parts = absl::StrSplit(place, '/');
  int index = 0, count = 0;
  return parts.size() == 2 && absl::SimpleAtoi(parts[0], &index) &&
         absl::SimpleAtoi(parts[1], &count) && index >= 0 && index < count &&
         tpr::gateway::ShardPlaceOf(index, count) == place;
}

}  // namespace

absl::StatusOr<std::string> ShardPlace::Stored() const {
  const RocksHandles rocks = storage_->rocks();
  std::string value;
  const rocksdb::Status s =
      rocks.db->Get(rocksdb::ReadOptions(), rocks.meta, kShardPlaceKey, &value);
  if (s.IsNotFound()) return std::string();
  if (!s.ok()) {
    return absl::UnavailableError(
        absl::StrCat("cannot read the shard place: ", s.ToString()));
  }
  return value;
}

absl::Status ShardPlace::Check(absl::string_view claimed, bool may_store) {
  if (claimed.empty()) return absl::OkStatus();
  if (!WellFormed(claimed)) {
    return absl::InvalidArgumentError(
        absl::StrCat(tpr::gateway::kShardPlaceHeader, ": '", claimed,
                     "' is not I/N (shard I of N, 0 <= I < N)"));
  }
  tpr::common::MutexLock lock(&mu_);
  if (known_.empty()) {
    absl::StatusOr<std::string> stored = Stored();
    if (!stored.ok()) return stored.status();
    known_ = *stored;
  }
  if (known_.empty() && !may_store) return absl::OkStatus();
  if (known_.empty()) {
    const RocksHandles rocks = storage_->rocks();
    rocksdb::WriteOptions sync;
    sync.sync = true;
    const rocksdb::Status s =
        rocks.db->Put(sync, rocks.meta, kShardPlaceKey, std::string(claimed));
    if (!s.ok()) {
      return absl::UnavailableError(
          absl::StrCat("cannot store the shard place: ", s.ToString()));
    }
    known_ = std::string(claimed);
  }
  if (known_ != claimed) {
    return absl::FailedPreconditionError(absl::StrCat(
        "this indexer is shard ", known_, " of its gateway's shard map (kept ",
        "in ", storage_->dir(), "), but the call comes from a gateway that ",
        "has it as shard ", claimed,
        ": the gateway lists its shards in another order"));
  }
  return absl::OkStatus();
}

}  // namespace tpr::indexer
