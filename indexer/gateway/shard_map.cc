#include "indexer/gateway/shard_map.h"

#include <algorithm>
#include <set>
#include <utility>

#include "absl/strings/escaping.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"

namespace tpr::gateway {

namespace {

constexpr uint64_t kFnvOffsetBasis = 14695981039346656037ull;
constexpr uint64_t kFnvPrime = 1099511628211ull;
constexpr absl::string_view kTokenMagic = "tprgw2";
// Salt of the indexer page token's checksum.
constexpr absl::string_view kIndexerTokenSalt = "tpr-indexer-list-1:";

// The 16 hex digits of the checksum the List tokens carry.
std::string TokenChecksum(absl::string_view salt, absl::string_view raw) {
  return absl::StrCat(
      absl::Hex(Fnv1a64(absl::StrCat(salt, raw)), absl::kZeroPad16));
}

// Checks "HOST:PORT" (HOST may be a bracketed IPv6 literal).
absl::Status CheckAddress(absl::string_view address, absl::string_view where) {
  const size_t colon = address.rfind(':');
  int port = 0;
  if (colon == absl::string_view::npos || colon == 0 ||
      !absl::SimpleAtoi(address.substr(colon + 1), &port) || port < 1 ||
      port > 65535) {
    return absl::InvalidArgumentError(absl::StrCat(
        where, ": '", address, "' is not HOST:PORT with a port in 1..65535"));
  }
  return absl::OkStatus();
}

// Adds one shard, checking its addresses and that none was listed before.
absl::Status AddShard(const std::vector<std::string>& addresses,
                      absl::string_view where, std::set<std::string>* seen,
                      ShardMap* map) {
  if (addresses.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": no address"));
  }
  ShardAddresses shard;
  for (size_t i = 0; i < addresses.size(); ++i) {
    if (absl::Status s = CheckAddress(addresses[i], where); !s.ok()) return s;
    if (!seen->insert(addresses[i]).second) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": '", addresses[i], "' is listed twice"));
    }
    if (i == 0) {
      shard.primary = addresses[i];
    } else {
      shard.replicas.push_back(addresses[i]);
    }
  }
  map->shards.push_back(std::move(shard));
  return absl::OkStatus();
}

}  // namespace

uint64_t Fnv1a64(absl::string_view bytes) {
  uint64_t hash = kFnvOffsetBasis;
  for (const char c : bytes) {
    hash ^= static_cast<uint64_t>(static_cast<unsigned char>(c));
    hash *= kFnvPrime;
  }
  return hash;
}

int ShardOf(absl::string_view id, int shard_count) {
  return static_cast<int>(Fnv1a64(id) % static_cast<uint64_t>(shard_count));
}

absl::StatusOr<ShardMap> ParseShardMap(absl::string_view text) {
  ShardMap map;
  std::set<std::string> seen;
  int line_number = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    const size_t hash = line.find('#');
    if (hash != absl::string_view::npos) line = line.substr(0, hash);
    std::vector<std::string> addresses =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (addresses.empty()) continue;
    if (absl::Status s =
            AddShard(addresses, absl::StrCat("shard map line ", line_number),
                     &seen, &map);
        !s.ok()) {
      return s;
    }
  }
  if (map.shards.empty())
    return absl::InvalidArgumentError("shard map lists no shard");
  return map;
}

absl::StatusOr<ShardMap> ParseShardFlags(
    const std::vector<std::string>& shards) {
  ShardMap map;
  std::set<std::string> seen;
  for (size_t i = 0; i < shards.size(); ++i) {
    std::vector<std::string> addresses =
        absl::StrSplit(shards[i], ',', absl::SkipEmpty());
    if (absl::Status s = AddShard(
            addresses, absl::StrCat("--shard #", i + 1, " (shard ", i, ")"),
            &seen, &map);
        !s.ok()) {
      return s;
    }
  }
  if (map.shards.empty()) return absl::InvalidArgumentError("no --shard given");
  return map;
}

std::string ShardPlaceOf(int shard, int shard_count) {
  return absl::StrCat(shard, "/", shard_count);
}

std::string EncodeIndexerListToken(absl::string_view after) {
  return absl::WebSafeBase64Escape(
      absl::StrCat(TokenChecksum(kIndexerTokenSalt, after), after));
}

absl::StatusOr<std::string> DecodeIndexerListToken(absl::string_view token) {
  if (token.empty()) return std::string();
  std::string raw;
  if (!absl::WebSafeBase64Unescape(token, &raw) || raw.size() < 16 ||
      TokenChecksum(kIndexerTokenSalt, absl::string_view(raw).substr(16)) !=
          absl::string_view(raw).substr(0, 16)) {
    return absl::InvalidArgumentError(
        "page_token is malformed (not a next_page_token of this indexer)");
  }
  return raw.substr(16);
}

std::string EncodeListToken(const std::vector<ListPosition>& positions) {
  std::string raw = absl::StrCat(kTokenMagic, ":", positions.size(), ":");
  for (const ListPosition& p : positions) {
    if (p.done) {
      raw += "d";
    } else {
      absl::StrAppend(&raw, "a", p.after.size(), ":", p.after);
    }
  }
  return absl::WebSafeBase64Escape(
      absl::StrCat(raw, TokenChecksum(kTokenMagic, raw)));
}

absl::StatusOr<std::vector<ListPosition>> DecodeListToken(
    absl::string_view token, int shard_count) {
  std::vector<ListPosition> positions(static_cast<size_t>(shard_count));
  if (token.empty()) return positions;
  const absl::Status malformed = absl::InvalidArgumentError(
      "page_token is malformed (not a gateway List token)");
  std::string sealed;
  if (!absl::WebSafeBase64Unescape(token, &sealed) || sealed.size() < 16)
    return malformed;
  const absl::string_view raw =
      absl::string_view(sealed).substr(0, sealed.size() - 16);
  if (TokenChecksum(kTokenMagic, raw) !=
      absl::string_view(sealed).substr(sealed.size() - 16)) {
    return malformed;
  }
  absl::string_view rest = raw;
  if (!absl::ConsumePrefix(&rest, absl::StrCat(kTokenMagic, ":")))
    return malformed;
  const size_t colon = rest.find(':');
  int count = 0;
  if (colon == absl::string_view::npos ||
      !absl::SimpleAtoi(rest.substr(0, colon), &count)) {
    return malformed;
  }
  if (count != shard_count) {
    return absl::InvalidArgumentError(
        absl::StrCat("page_token was made for ", count,
                     " shards; this gateway has ", shard_count));
  }
  rest.remove_prefix(colon + 1);
  for (ListPosition& p : positions) {
    if (absl::ConsumePrefix(&rest, "d")) {
      p.done = true;
      continue;
    }
    if (!absl::ConsumePrefix(&rest, "a")) return malformed;
    const size_t end = rest.find(':');
    size_t size = 0;
    if (end == absl::string_view::npos ||
        !absl::SimpleAtoi(rest.substr(0, end), &size) ||
        rest.size() - end - 1 < size) {
      return malformed;
    }
    p.after = std::string(rest.substr(end + 1, size));
    rest.remove_prefix(end + 1 + size);
  }
  if (!rest.empty()) return malformed;
  return positions;
}

ListMerge MergeListPages(const std::vector<ListPosition>& positions,
                         const std::vector<ShardPage>& pages,
                         size_t page_size) {
  const size_t shards = pages.size();
  ListMerge merge;
  merge.positions = positions;
  // Ids above the smallest next token of a shard with more to list cannot
  // be placed yet: that shard's next page may hold smaller ones.
  const std::string* bound = nullptr;
  for (const ShardPage& page : pages) {
    if (!page.next_token.empty() &&
        (bound == nullptr || page.next_token < *bound)) {
      bound = &page.next_token;
    }
  }
  std::vector<size_t> next(shards, 0);
  while (merge.taken.size() < page_size) {
    int best = -1;
    for (size_t s = 0; s < shards; ++s) {
      if (next[s] == pages[s].ids.size()) continue;
      const std::string& id = pages[s].ids[next[s]];
      if (bound != nullptr && id > *bound) continue;
      if (best < 0 || id < pages[static_cast<size_t>(best)]
                               .ids[next[static_cast<size_t>(best)]]) {
        best = static_cast<int>(s);
      }
    }
    if (best < 0) break;
    merge.taken.emplace_back(best,
                             static_cast<int>(next[static_cast<size_t>(best)]));
    ++next[static_cast<size_t>(best)];
  }
  for (size_t s = 0; s < shards; ++s) {
    ListPosition& p = merge.positions[s];
    if (p.done) continue;
    const ShardPage& page = pages[s];
    if (next[s] == page.ids.size()) {
      // The whole page was placed: continue where the shard said.
      if (page.next_token.empty()) {
        p.done = true;
      } else {
        p.after = page.next_token;
      }
    } else if (next[s] > 0) {
      p.after = page.ids[next[s] - 1];
    }
    if (!p.done) merge.last = false;
  }
  return merge;
}

}  // namespace tpr::gateway
