// The gateway's routing part, without the wire: which shard owns an id, the
// shard map (each shard's primary and replica addresses), the order in which
// the gateway merges the shards' search streams, and the List page token
// that carries every shard's position.
//
//   absl::StatusOr<ShardMap> map = ParseShardMap(file_text);
//   int shard = ShardOf("dog/dog_3.off", map->shards.size());
//
// Sharding: a fixed number S of shards; an id belongs to shard
// Fnv1a64(UTF-8 bytes of the id) mod S. FNV-1a is stable across builds,
// platforms and languages (std::hash is not), so a data directory written
// under one gateway build is routed the same way by the next. Changing S
// moves ids between shards, and every shard keeps its place (shard I of N,
// kShardPlaceHeader): resharding is an offline re-ingest
// (docs/scale-out.md).
//
// No gRPC, no Protobuf: unit-tested on its own.
#ifndef TPR_INDEXER_GATEWAY_SHARD_MAP_H_
#define TPR_INDEXER_GATEWAY_SHARD_MAP_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace tpr::gateway {

// Fnv1a64 returns the 64-bit FNV-1a hash of `bytes` (offset basis
// 14695981039346656037, prime 1099511628211; the published test vectors hold,
// e.g. Fnv1a64("") = 0xcbf29ce484222325, Fnv1a64("a") = 0xaf63dc4c8601ec8c).
// Cost O(size). Thread-safe.
uint64_t Fnv1a64(absl::string_view bytes);

// ShardOf returns the shard owning `id`: Fnv1a64(id) mod shard_count.
// Precondition: shard_count >= 1. Cost O(size of id). Thread-safe.
int ShardOf(absl::string_view id, int shard_count);

// kShardPlaceHeader: the metadata key of every call the gateway makes to a
// shard, value "I/N" (ShardPlaceOf): the shard's place in the map. The
// shard keeps the first place it is given and refuses any other
// (indexer/service/shard_place.h), so that a map listing the same shards in
// another order is refused rather than routing ids to the wrong shard.
inline constexpr char kShardPlaceHeader[] = "tpr-shard-place";

// ShardPlaceOf returns "I/N" for shard `shard` of `shard_count`.
std::string ShardPlaceOf(int shard, int shard_count);

// ShardAddresses: how one shard is reached.
struct ShardAddresses {
  // HOST:PORT of the shard's primary: every write goes there. Required.
  std::string primary;
  // HOST:PORT of its read replicas (followers), possibly none. Reads go to
  // any serving address among the primary and these.
  std::vector<std::string> replicas;
};

// ShardMap: the fixed list of shards; shard i is shards[i].
struct ShardMap {
  std::vector<ShardAddresses> shards;
};

// ParseShardMap reads the shard map file format: one shard per line, in
// shard order, "PRIMARY [REPLICA ...]" separated by spaces or tabs; '#'
// starts a comment; blank lines are ignored. Example, two shards, the first
// with one replica:
//   127.0.0.1:7100 127.0.0.1:7101
//   127.0.0.1:7110
// Returns INVALID_ARGUMENT naming the line for an address that is not
// HOST:PORT, an address listed twice, or no shard at all. Cost O(size).
absl::StatusOr<ShardMap> ParseShardMap(absl::string_view text);

// ParseShardFlags builds a map from one string per shard,
// "PRIMARY[,REPLICA...]" (the gateway's repeated --shard flag). Errors as
// ParseShardMap, naming the flag's position.
absl::StatusOr<ShardMap> ParseShardFlags(
    const std::vector<std::string>& shards);

// RanksBefore is the order of search results, the same as one tpr-indexer's
// (indexer/lib/signature_index.h): ascending distance, then ascending id
// (bytewise). The gateway's merge must use exactly this order for its
// answers to equal one indexer's, ties included.
inline bool RanksBefore(double distance_a, const std::string& id_a,
                        double distance_b, const std::string& id_b) {
  if (distance_a != distance_b) return distance_a < distance_b;
  return id_a < id_b;
}

// ListPosition: where one shard's listing stands between gateway pages.
struct ListPosition {
  // True when the shard has nothing more to list.
  bool done = false;
  // The last id already returned from this shard; empty before its first.
  // The next shard page starts after it (the shard's page token is
  // EncodeIndexerListToken of it).
  std::string after;
};

// EncodeIndexerListToken returns one tpr-indexer's List page token for the
// page that starts after id `after`: web-safe base64 of a 16-hex-digit
// checksum (FNV-1a of a salt and the id) followed by the id, so that a
// token is opaque and a damaged or invented one is refused. Cost O(size).
std::string EncodeIndexerListToken(absl::string_view after);

// DecodeIndexerListToken returns the id a token from EncodeIndexerListToken
// starts after ("" for the empty token, the first page). Returns
// INVALID_ARGUMENT naming page_token for anything else. Cost O(size).
absl::StatusOr<std::string> DecodeIndexerListToken(absl::string_view token);

// EncodeListToken returns the gateway's List page token for `positions`
// (one per shard): web-safe base64 of "tprgw2", the shard count, each
// position (length-prefixed ids, so ids of any bytes survive) and a
// 16-hex-digit checksum of them all. Cost O(size).
std::string EncodeListToken(const std::vector<ListPosition>& positions);

// DecodeListToken parses a token from EncodeListToken. An empty token is the
// first page (every shard at its start). Returns INVALID_ARGUMENT naming
// page_token for a malformed or damaged token (the checksum differs) or one
// made for a different number of shards.
absl::StatusOr<std::vector<ListPosition>> DecodeListToken(
    absl::string_view token, int shard_count);

// ShardPage: the ids of one shard's List page, ascending, and the shard's
// next page token (empty when it has nothing after them).
struct ShardPage {
  std::vector<std::string> ids;
  std::string next_token;
};

// ListMerge: one merged gateway page.
struct ListMerge {
  // (shard, index into that shard's page ids) of the models on the page, in
  // ascending id order.
  std::vector<std::pair<int, int>> taken;
  // Every shard's position after the page.
  std::vector<ListPosition> positions;
  // True when no shard has anything left (no next page token).
  bool last = true;
};

// MergeListPages merges shard pages fetched at `positions` into one page of
// at most `page_size` ids in ascending order. Shards already done have an
// empty page. An id is taken only when no shard with more to list could
// still hold a smaller one (it is at most every such shard's next token), so
// pages never skip or repeat an id, even when a shard's page came back short
// (models deleted meanwhile). Preconditions: pages.size() == positions.size();
// each page's ids ascending; ids unique across shards (each id has one owner).
// Cost O(total ids log shards).
ListMerge MergeListPages(const std::vector<ListPosition>& positions,
                         const std::vector<ShardPage>& pages, size_t page_size);

}  // namespace tpr::gateway

#endif  // TPR_INDEXER_GATEWAY_SHARD_MAP_H_
