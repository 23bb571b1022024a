// A shard's place in its gateway's shard map ("I/N": shard I of N), fixed
// the first time a gateway names it and kept in the shard's RocksDB (key
// "shard_place" of the "default" family; replicated to followers with
// every other write). tpr-gateway sends its map's place of every shard with
// every call (metadata tpr::gateway::kShardPlaceHeader); the shard refuses a
// call that names another place, so that a gateway given its shards in another
// order cannot route ids to the wrong shard. A call without the header (a
// client talking to one indexer) is not checked.
//
//   ShardPlace place(&core->storage());
//   if (absl::Status s = place.Check(claimed); !s.ok()) return s;
//
// Changing a shard's place (resharding) is an offline procedure:
// docs/scale-out.md.
#ifndef TPR_INDEXER_SERVICE_SHARD_PLACE_H_
#define TPR_INDEXER_SERVICE_SHARD_PLACE_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "common/mutex.h"
#include "indexer/gateway/shard_map.h"
#include "indexer/service/storage.h"

namespace tpr::indexer {

// ShardPlace: the stored place of one indexer and the check of a call's
// claimed place. Thread-safe. `storage` must outlive it.
class ShardPlace {
 public:
  explicit ShardPlace(Storage* storage) : storage_(storage) {}

  // Check accepts `claimed` ("I/N"; empty: not checked) when it equals the
  // stored place, and, when none is stored yet, stores it (one synced
  // write) if `may_store` (a primary; a follower gets its primary's place
  // through replication) or accepts it unchecked otherwise.
  // Returns INVALID_ARGUMENT naming the header when `claimed` is not
  // "I/N", FAILED_PRECONDITION naming both places when another is stored,
  // the store's error when it cannot be read or written. Cost: O(1) once
  // the place is known; one read (and one synced write) before.
  absl::Status Check(absl::string_view claimed, bool may_store = true);

  // Stored returns the stored place, "" when none is, or the store's error.
  // Cost: one point lookup.
  absl::StatusOr<std::string> Stored() const;

 private:
  Storage* const storage_;
  tpr::common::Mutex mu_;
  std::string known_ ABSL_GUARDED_BY(mu_);  // "" until read or stored
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_SHARD_PLACE_H_
