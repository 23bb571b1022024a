// The gateway's routing part: the FNV-1a hash against the published test
// vectors, the id -> shard rule, the shard map parsers' errors, the List
// page token, and the List page merge against a sorted-list oracle.
#include "indexer/gateway/shard_map.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>

#include "absl/strings/str_cat.h"

namespace tpr::gateway {
namespace {

TEST(Fnv1a64Test, PublishedTestVectors) {
  // From the FNV reference (Fowler/Noll/Vo, "FNV-1a 64-bit" test suite).
  EXPECT_EQ(Fnv1a64(""), 0xcbf29ce484222325ull);
  EXPECT_EQ(Fnv1a64("a"), 0xaf63dc4c8601ec8cull);
  EXPECT_EQ(Fnv1a64("foobar"), 0x85944171f73967e8ull);
}

TEST(ShardOfTest, StableDocumentedRule) {
  // Pinned values: changing the rule would move every stored id.
  EXPECT_EQ(ShardOf("a", 3), static_cast<int>(0xaf63dc4c8601ec8cull % 3));
  EXPECT_EQ(ShardOf("foobar", 4), static_cast<int>(0x85944171f73967e8ull % 4));
  EXPECT_EQ(ShardOf("anything", 1), 0);
  // Bytes, not characters: UTF-8 ids hash their encoding.
  EXPECT_EQ(ShardOf("\xc3\xa9", 7), static_cast<int>(Fnv1a64("\xc3\xa9") % 7));
}

TEST(ShardOfTest, SpreadsIdsEvenly) {
  std::vector<int> counts(4, 0);
  for (int i = 0; i < 40000; ++i) ++counts[ShardOf(absl::StrCat("m", i), 4)];
  for (int c : counts) {
    EXPECT_GT(c, 9400);
    EXPECT_LT(c, 10600);
  }
}

TEST(ParseShardMapTest, ReadsShardsInOrder) {
  absl::StatusOr<ShardMap> map = ParseShardMap(
      "# three shards\n127.0.0.1:7100 127.0.0.1:7101\n\n"
      "  host-b:7110\t# no replica\n[::1]:7120 [::1]:7121 [::1]:7122\n");
  ASSERT_TRUE(map.ok()) << map.status();
  ASSERT_EQ(map->shards.size(), 3u);
  EXPECT_EQ(map->shards[0].primary, "127.0.0.1:7100");
  EXPECT_EQ(map->shards[0].replicas,
            std::vector<std::string>{"127.0.0.1:7101"});
  EXPECT_EQ(map->shards[1].primary, "host-b:7110");
  EXPECT_TRUE(map->shards[1].replicas.empty());
  EXPECT_EQ(map->shards[2].replicas.size(), 2u);
}

TEST(ParseShardMapTest, ErrorsNameTheLine) {
  absl::StatusOr<ShardMap> bad_port = ParseShardMap("a:1\nb:99999\n");
  EXPECT_TRUE(absl::IsInvalidArgument(bad_port.status()));
  EXPECT_NE(bad_port.status().message().find("line 2"), std::string::npos);
  absl::StatusOr<ShardMap> twice = ParseShardMap("a:1 b:2\nb:2\n");
  EXPECT_TRUE(absl::IsInvalidArgument(twice.status()));
  EXPECT_NE(twice.status().message().find("listed twice"), std::string::npos);
  EXPECT_TRUE(absl::IsInvalidArgument(ParseShardMap("# nothing\n\n").status()));
  EXPECT_TRUE(absl::IsInvalidArgument(ParseShardMap("noport\n").status()));
}

TEST(ParseShardFlagsTest, PrimaryThenReplicas) {
  absl::StatusOr<ShardMap> map = ParseShardFlags({"a:1,a:2,a:3", "b:1"});
  ASSERT_TRUE(map.ok()) << map.status();
  EXPECT_EQ(map->shards[0].primary, "a:1");
  EXPECT_EQ(map->shards[0].replicas, (std::vector<std::string>{"a:2", "a:3"}));
  absl::StatusOr<ShardMap> bad = ParseShardFlags({"a:1", "b"});
  EXPECT_TRUE(absl::IsInvalidArgument(bad.status()));
  EXPECT_NE(bad.status().message().find("shard 1"), std::string::npos);
  EXPECT_TRUE(absl::IsInvalidArgument(ParseShardFlags({}).status()));
}

TEST(ListTokenTest, RoundTripsAnyIdBytes) {
  std::vector<ListPosition> positions(3);
  positions[0].after = std::string("with:colon\nnewline\0zero", 23);
  positions[1].done = true;
  const std::string token = EncodeListToken(positions);
  absl::StatusOr<std::vector<ListPosition>> back = DecodeListToken(token, 3);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ((*back)[0].after, positions[0].after);
  EXPECT_FALSE((*back)[0].done);
  EXPECT_TRUE((*back)[1].done);
  EXPECT_EQ((*back)[2].after, "");
  EXPECT_FALSE((*back)[2].done);
}

TEST(ListTokenTest, RejectsForeignTokens) {
  EXPECT_EQ(DecodeListToken("", 4)->size(), 4u);
  absl::Status other_count =
      DecodeListToken(EncodeListToken(std::vector<ListPosition>(2)), 3)
          .status();
  EXPECT_TRUE(absl::IsInvalidArgument(other_count));
  EXPECT_NE(other_count.message().find("2 shards"), std::string::npos);
  EXPECT_TRUE(absl::IsInvalidArgument(
      DecodeListToken("m00012", 3).status()));  // an indexer's
  EXPECT_TRUE(absl::IsInvalidArgument(DecodeListToken("!!!", 3).status()));
}

// Simulates shards serving List pages of a fixed id set, as tpr-indexer
// does: a page scans up to page_size ids after the token and its token is
// the last id scanned; in half the trials some scanned ids vanish from the
// answer (deleted between the scan and the read), so pages come back short.
// Paging through the merge (with the token round-tripped) must list every
// id that did not vanish, in order, once.
TEST(MergeListPagesTest, PagesEqualTheSortedSetWithoutGapsOrRepeats) {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 80; ++trial) {
    const int shards = 1 + trial % 4;
    const bool short_pages = trial % 2 == 1;
    std::vector<std::vector<std::string>> held(static_cast<size_t>(shards));
    std::set<std::string> vanishing;
    std::set<std::string> expected;
    const int n = static_cast<int>(rng() % 200);
    for (int i = 0; i < n; ++i) {
      std::string id = absl::StrCat("id", rng() % 100000);
      if (expected.count(id) || vanishing.count(id)) continue;
      if (short_pages && rng() % 3 == 0) {
        vanishing.insert(id);
      } else {
        expected.insert(id);
      }
      held[static_cast<size_t>(ShardOf(id, shards))].push_back(id);
    }
    for (auto& ids : held) std::sort(ids.begin(), ids.end());
    const size_t page_size = 1 + rng() % 25;
    std::vector<std::string> listed;
    std::vector<ListPosition> positions(static_cast<size_t>(shards));
    bool finished = false;
    for (int page = 0; page < 1000 && !finished; ++page) {
      std::vector<ShardPage> pages(static_cast<size_t>(shards));
      for (size_t s = 0; s < pages.size(); ++s) {
        if (positions[s].done) continue;
        const std::vector<std::string>& ids = held[s];
        auto it =
            positions[s].after.empty()
                ? ids.begin()
                : std::upper_bound(ids.begin(), ids.end(), positions[s].after);
        std::string last_scanned;
        for (size_t scanned = 0; it != ids.end() && scanned < page_size;
             ++it, ++scanned) {
          if (!vanishing.count(*it)) pages[s].ids.push_back(*it);
          last_scanned = *it;
        }
        if (it != ids.end()) pages[s].next_token = last_scanned;
      }
      ListMerge merge = MergeListPages(positions, pages, page_size);
      ASSERT_LE(merge.taken.size(), page_size);
      for (const auto& [s, i] : merge.taken) {
        listed.push_back(
            pages[static_cast<size_t>(s)].ids[static_cast<size_t>(i)]);
      }
      finished = merge.last;
      absl::StatusOr<std::vector<ListPosition>> next =
          DecodeListToken(EncodeListToken(merge.positions), shards);
      ASSERT_TRUE(next.ok());
      positions = *next;
    }
    EXPECT_TRUE(finished);
    EXPECT_EQ(listed,
              std::vector<std::string>(expected.begin(), expected.end()))
        << "trial " << trial << " shards " << shards << " page " << page_size;
  }
}

}  // namespace
}  // namespace tpr::gateway
