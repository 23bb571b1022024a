// CentroidTable against its oracles, EmdLowerBound (emd.h, the centroid
// bound in double) and the exact Emd: the table's float32 rows must give a
// bound that never exceeds EmdLowerBound and is below it by no more than
// the float32 rounding of the centroid allows, including across signatures
// with different band counts (rows are zero-padded) and for absent slots.
#include "indexer/lib/centroid_table.h"

#include <algorithm>
#include <cmath>
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
        // Float32 rounding moves each centroid value by at most 2^-24 of
        // itself, so N(c - fl32(c)) <= 2^-24 N(c); the bound subtracts
        // that radius once and the distance to fl32(c) may be short by it
        // once more.
        const std::vector<double> c = Centroid(items[i]);
        const std::vector<double> zero(c.size(), 0.0);
        const double norm_c =
            CentroidBound(c.data(), items[i].bands(), zero.data(), items[i].bands());
        const double slack = 2.0 * std::ldexp(norm_c, -24) * (1.0 + 1e-9) + 1e-14 * want;
        EXPECT_LE(got, want) << "slot " << i << " query bands " << bands;
        EXPECT_GE(got, want - slack) << "slot " << i << " query bands " << bands;
        EXPECT_LE(got, Emd(q, items[i])) << "slot " << i;
        EXPECT_GT(want, 0.0);  // distinct random signatures: a real bound
        largest_gap = std::max(largest_gap, (want - got) / want);
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 16 * 20);
  // The float32 rows lose no pruning power to speak of.
  EXPECT_LT(largest_gap, 1e-6);
}

TEST(CentroidTableTest, ExactWhereTheCentroidIsRepresentable) {
  // One feature with float32-exact coordinates and weight 1: the centroid
  // is the point itself, exact in float32, so the rounding radius is 0 and
  // the table's bound equals EmdLowerBound bit for bit (which equals the
  // ground distance here: both signatures are single points).
  Signature a;
  a.features.push_back(
      {1.0, 0.5, std::vector<double>(20, 0.25), std::vector<double>(20, 0.125),
       std::vector<double>(20, 0.75)});
  Signature b = a;
  b.features[0].integral_geodesic = 0.25;
  b.features[0].curvature.assign(20, 0.5);
  GroundDistanceOptions o;  // powers of two: every phi(U) value exact
  o.w1 = o.w2 = o.w3 = o.w4 = 0.25;
  o.k_scale = o.a_scale = o.h_scale = 1.0;
  o.spectral.weight = 0.0;
  const PreparedSignature pa = *Prepare(a, o);
  const PreparedSignature pb = *Prepare(b, o);
  const CentroidTable table = CentroidTable::Build(
      1, [&](uint32_t) -> const PreparedSignature* { return &pb; });
  const std::vector<double> qa = Centroid(pa);
  const double got = table.LowerBound(qa.data(), pa.bands(), 0);
  EXPECT_TRUE(SameBits(got, EmdLowerBound(pa, pb))) << got;
  EXPECT_NEAR(got, GroundDistance(pa, 0, pb, 0), 1e-12);
  EXPECT_GT(got, 0.0);
}

}  // namespace
}  // namespace tpr::index
