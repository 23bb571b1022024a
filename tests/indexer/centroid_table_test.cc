// CentroidTable against its oracle, EmdLowerBound (emd.h): the table must
// give the same bound bit for bit, including across signatures with
// different band counts (rows are zero-padded) and for absent slots.
#include "indexer/lib/centroid_table.h"

#include <cstring>
#include <vector>

#include <gtest/gtest.h>

#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

using testing::SignatureGenerator;
using testing::SignatureGeneratorOptions;

std::vector<PreparedSignature> Draw(int bands, int count, uint64_t seed) {
  SignatureGeneratorOptions o;
  o.seed = seed;
  o.bands = bands;
  o.classes = 3;
  o.features = 8;
  SignatureGenerator gen(o);
  std::vector<PreparedSignature> out;
  for (int i = 0; i < count; ++i) {
    absl::StatusOr<PreparedSignature> p =
        Prepare(gen.Next(), GroundDistanceOptions{});
    EXPECT_TRUE(p.ok()) << p.status();
    out.push_back(*std::move(p));
  }
  return out;
}

bool SameBits(double a, double b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

TEST(CentroidTableTest, EmptyTable) {
  const CentroidTable t =
      CentroidTable::Build(0, [](uint32_t) -> const PreparedSignature* {
        return nullptr;
      });
  EXPECT_EQ(t.size(), 0u);
}

TEST(CentroidTableTest, BitIdenticalToEmdLowerBoundAcrossBandCounts) {
  // Items with 12, 20 and 25 bands in one table, every third slot absent.
  std::vector<PreparedSignature> items;
  uint64_t seed = 7;
  for (int bands : {20, 12, 25}) {
    for (PreparedSignature& p : Draw(bands, 10, seed++)) {
      items.push_back(std::move(p));
    }
  }
  auto present = [](uint32_t i) { return i % 3 != 1; };
  const CentroidTable table = CentroidTable::Build(
      items.size(), [&](uint32_t i) -> const PreparedSignature* {
        return present(i) ? &items[i] : nullptr;
      });
  ASSERT_EQ(table.size(), items.size());
  int compared = 0;
  // Queries with fewer, equal, more bands than the table's widest row.
  for (int bands : {12, 20, 25, 31}) {
    for (const PreparedSignature& q : Draw(bands, 4, 100 + bands)) {
      for (uint32_t i = 0; i < items.size(); ++i) {
        const double got = table.LowerBound(q, i);
        if (!present(i)) {
          EXPECT_TRUE(SameBits(got, 0.0)) << i;
          continue;
        }
        const double want = EmdLowerBound(q, items[i]);
        EXPECT_TRUE(SameBits(got, want))
            << "slot " << i << " query bands " << bands << ": " << got
            << " vs " << want;
        EXPECT_GT(want, 0.0);  // distinct random signatures: a real bound
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 16 * 20);
}

}  // namespace
}  // namespace tpr::index
