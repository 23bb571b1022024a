// CentroidTable against its oracles, EmdLowerBound (emd.h, the centroid
// bound in double) and the exact Emd: the table's float32 rows must give a
// bound that never exceeds EmdLowerBound and is below it by no more than
// the float32 rounding of the centroid allows, including across signatures
// with different band counts (rows are zero-padded) and for absent slots.
#include "indexer/lib/centroid_table.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

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

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST(CentroidTableTest, EmptyTable) {
  const CentroidTable t = CentroidTable::Build(
      0, [](uint32_t) -> const PreparedSignature* { return nullptr; });
  EXPECT_EQ(t.size(), 0u);
}

TEST(CentroidTableTest, NeverAboveEmdLowerBoundAndWithinFloatRounding) {
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
  double largest_gap = 0.0;
  // Queries with fewer, equal, more bands than the table's widest row.
  for (int bands : {12, 20, 25, 31}) {
    for (const PreparedSignature& q : Draw(bands, 4, 100 + bands)) {
      const std::vector<double> qc = Centroid(q);
      for (uint32_t i = 0; i < items.size(); ++i) {
        const double got = table.LowerBound(qc.data(), q.bands(), i);
        if (!present(i)) {
          EXPECT_TRUE(SameBits(got, 0.0)) << i;
          continue;
        }
        const double want = EmdLowerBound(q, items[i]);
        // Quantization (centroid_table.cc) moves g by at most 2^-24 of
        // itself and each band value by at most half its block's step,
        // max|block| / 32767, so N(c - c~) <= r below; the bound subtracts
        // a radius e <= r (1 + 1e-9) once and the distance to c~ may be
        // short by it once more.
        const std::vector<double> c = Centroid(items[i]);
        const int ib = items[i].bands();
        double r = std::ldexp(std::abs(c[0]), -24);
        for (int block = 0; block < 3; ++block) {
          double largest = 0.0;
          for (int d = 0; d < ib; ++d)
            largest = std::max(largest, std::abs(c[1 + block * ib + d]));
          r += std::sqrt(static_cast<double>(ib)) * 0.5 * largest / 32767.0 *
               (1.0 + 1e-6);
        }
        const double slack = 2.0 * r * (1.0 + 1e-9) + 1e-14 * want;
        EXPECT_LE(got, want) << "slot " << i << " query bands " << bands;
        EXPECT_GE(got, want - slack)
            << "slot " << i << " query bands " << bands;
        EXPECT_LE(got, Emd(q, items[i])) << "slot " << i;
        EXPECT_GT(want, 0.0);  // distinct random signatures: a real bound
        largest_gap = std::max(largest_gap, (want - got) / want);
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 16 * 20);
  // The quantized rows lose little pruning power.
  EXPECT_LT(largest_gap, 1e-3);
  EXPECT_GT(largest_gap, 0.0);  // the radius is subtracted
}

TEST(CentroidTableTest, AnItemIsAtBoundZeroFromItself) {
  // The radius covers the quantization of the item's own centroid, so the
  // bound between a signature and itself is exactly 0, never a positive
  // value that would prune an exact match.
  std::vector<PreparedSignature> items = Draw(20, 12, 3);
  const CentroidTable table = CentroidTable::Build(
      items.size(),
      [&](uint32_t i) -> const PreparedSignature* { return &items[i]; });
  for (uint32_t i = 0; i < items.size(); ++i) {
    const std::vector<double> c = Centroid(items[i]);
    EXPECT_EQ(table.LowerBound(c.data(), items[i].bands(), i), 0.0) << i;
  }
}

}  // namespace
}  // namespace tpr::index
