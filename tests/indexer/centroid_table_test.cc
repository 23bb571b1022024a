// CentroidTable against its oracles, EmdLowerBound (emd.h, the centroid
// bound in double) and the exact Emd: the table's float32 rows must give a
// bound that never exceeds EmdLowerBound and is below it by no more than
// the float32 rounding of the centroid allows, including across signatures
// with different band counts (rows are zero-padded) and for absent slots.
// Its spectral bound likewise against SpectralDistance (metric.h), the
// exact spectral term, and the sum of both against the exact Distance.
#include "indexer/lib/centroid_table.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/metric.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

using testing::SignatureGenerator;
using testing::SignatureGeneratorOptions;

// PrepareAll returns `count` signatures of the generator `o`, prepared
// with `ground`.
std::vector<PreparedSignature> PrepareAll(const SignatureGeneratorOptions& o,
                                          const GroundDistanceOptions& ground,
                                          int count) {
  SignatureGenerator gen(o);
  std::vector<PreparedSignature> out;
  for (int i = 0; i < count; ++i) {
    absl::StatusOr<PreparedSignature> p = Prepare(gen.Next(), ground);
    EXPECT_TRUE(p.ok()) << p.status();
    out.push_back(*std::move(p));
  }
  return out;
}

// Draw prepares generated signatures with the default options, or with 10
// spectral values and no heat-trace term when `spectral` is false (other
// embedding sizes than the default's).
std::vector<PreparedSignature> Draw(int bands, int count, uint64_t seed,
                                    bool spectral = true) {
  SignatureGeneratorOptions o;
  o.seed = seed;
  o.bands = bands;
  o.classes = 3;
  o.features = 8;
  GroundDistanceOptions ground;
  if (!spectral) {
    ground.spectral.eigenvalues = 10;
    ground.heat.scales = 0;
  }
  return PrepareAll(o, ground, count);
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
        table.Prefetch(i);  // hints, absent slots too: no effect on bounds
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

// Signatures with 50-value spectra, prepared with the spectral term on
// (`transform`, weight 1, 20 eigenvalues: the index's default).
std::vector<PreparedSignature> DrawWithSpectra(int count, uint64_t seed,
                                               SpectralTransform transform) {
  SignatureGeneratorOptions o;
  o.seed = seed;
  o.classes = 4;
  o.features = 10;
  o.spectrum = 50;
  GroundDistanceOptions ground;
  ground.spectral.transform = transform;
  return PrepareAll(o, ground, count);
}

TEST(CentroidTableTest, SpectralBoundNeverAboveSpectralTermAndWithinRounding) {
  // Every transform (raw values grow with the index, log ones are small):
  // the table's one int16 step per table must stay a tight lower bound.
  for (SpectralTransform transform :
       {SpectralTransform::kByIndex, SpectralTransform::kRaw,
        SpectralTransform::kLog}) {
    std::vector<PreparedSignature> items = DrawWithSpectra(40, 11, transform);
    auto present = [](uint32_t i) { return i % 5 != 2; };
    const CentroidTable table = CentroidTable::Build(
        items.size(), [&](uint32_t i) -> const PreparedSignature* {
          return present(i) ? &items[i] : nullptr;
        });
    ASSERT_EQ(table.spectral_size(), 20);
    // The oracle of the radius: half a step per value, the step being the
    // table's largest |value| / 32767.
    double largest = 0.0;
    for (const PreparedSignature& p : items) {
      for (int k = 0; k < p.spectral_size(); ++k)
        largest = std::max(largest, std::abs(double{p.spectral()[k]}));
    }
    const double r = std::sqrt(20.0) * 0.5 * largest / 32767.0 * (1.0 + 1e-6);
    ASSERT_EQ(table.heat_size(), items[0].heat_size());
    double largest_heat = 0.0;
    for (const PreparedSignature& p : items) {
      for (int k = 0; k < p.heat_size(); ++k)
        largest_heat = std::max(largest_heat, std::abs(double{p.heat()[k]}));
    }
    const double rh = std::sqrt(static_cast<double>(table.heat_size())) * 0.5 *
                      largest_heat / 32767.0 * (1.0 + 1e-6);
    int compared = 0;
    double largest_gap = 0.0;
    for (const PreparedSignature& q : DrawWithSpectra(8, 99, transform)) {
      const std::vector<double> qc = Centroid(q);
      for (uint32_t i = 0; i < items.size(); ++i) {
        const double got =
            table.SpectralLowerBound(q.spectral(), q.spectral_size(), i);
        if (!present(i)) {
          EXPECT_TRUE(SameBits(got, 0.0)) << i;
          continue;
        }
        const double want = SpectralDistance(q, items[i]);
        EXPECT_LE(got, want) << "slot " << i;
        EXPECT_GE(got, want - 2.0 * r * (1.0 + 1e-9) - 1e-14 * want)
            << "slot " << i;
        // The whole level-1 bound of the index under EMD + S + H.
        const double heat = table.HeatLowerBound(q.heat(), q.heat_size(), i);
        const double want_heat = HeatDistance(q, items[i]);
        EXPECT_LE(heat, want_heat) << "slot " << i;
        EXPECT_GE(heat, want_heat - 2.0 * rh * (1.0 + 1e-9) - 1e-14 * want_heat)
            << "slot " << i;
        const TermWeights all{1, 1, 1};
        const double level1 =
            table.LowerBound(qc.data(), q.bands(), i) + got + heat;
        EXPECT_LE(level1, DistanceLowerBound(q, items[i], all)) << "slot " << i;
        EXPECT_LE(level1, Distance(q, items[i], all)) << "slot " << i;
        EXPECT_GT(want, 0.0);
        largest_gap = std::max(largest_gap, (want - got) / want);
        ++compared;
      }
      // A query whose embedding has another length gets no bound.
      EXPECT_EQ(table.SpectralLowerBound(q.spectral(), 19, 0), 0.0);
      EXPECT_EQ(table.HeatLowerBound(q.heat(), q.heat_size() - 1, 0), 0.0);
    }
    EXPECT_EQ(compared, 8 * 32);
    // Relative to the distance, which between two poses of a class can be
    // far below the table's largest value (log values).
    EXPECT_LT(largest_gap, 1e-2) << SpectralTransformName(transform);
    EXPECT_GT(largest_gap, 0.0);  // the radius is subtracted
    // An item is at spectral bound 0 from itself (its radius covers its
    // own quantization).
    for (uint32_t i = 0; i < items.size(); ++i) {
      EXPECT_EQ(table.SpectralLowerBound(items[i].spectral(),
                                         items[i].spectral_size(), i),
                0.0)
          << i;
      EXPECT_EQ(table.HeatLowerBound(items[i].heat(), items[i].heat_size(), i),
                0.0)
          << i;
    }
  }
}

TEST(CentroidTableTest, NoEmbeddingBoundWithoutOrWithMixedEmbeddings) {
  // 10 spectral values and no heat-trace term: 10 values kept, no heat
  // array at all.
  const std::vector<PreparedSignature> plain =
      Draw(20, 6, 5, /*spectral=*/false);
  const CentroidTable without = CentroidTable::Build(
      plain.size(),
      [&](uint32_t i) -> const PreparedSignature* { return &plain[i]; });
  EXPECT_EQ(without.spectral_size(), 10);
  EXPECT_EQ(without.heat_size(), 0);
  EXPECT_EQ(without.HeatLowerBound(nullptr, 0, 0), 0.0);
  std::vector<PreparedSignature> with =
      DrawWithSpectra(6, 5, SpectralTransform::kByIndex);
  const CentroidTable table = CentroidTable::Build(
      with.size(),
      [&](uint32_t i) -> const PreparedSignature* { return &with[i]; });
  const size_t heat = static_cast<size_t>(with[0].heat_size());
  ASSERT_GT(heat, 0u);
  // The extra spectral values per row; the heat array's radius and values.
  const size_t more = static_cast<size_t>(with[0].spectral_size() - 10);
  EXPECT_EQ(table.MemoryBytes(),
            without.MemoryBytes() +
                with.size() * (more * sizeof(int16_t) + sizeof(float) +
                               heat * sizeof(int16_t)));
  // Items of two embedding sizes in one table (never in one index): the
  // table keeps neither embedding and bounds nothing, still a lower bound.
  std::vector<const PreparedSignature*> mixed = {&plain[0], &with[0], &with[1]};
  const CentroidTable m =
      CentroidTable::Build(mixed.size(), [&](uint32_t i) { return mixed[i]; });
  EXPECT_EQ(m.spectral_size(), 0);
  EXPECT_EQ(m.heat_size(), 0);
  EXPECT_EQ(m.SpectralLowerBound(with[2].spectral(), 20, 1), 0.0);
  EXPECT_EQ(m.HeatLowerBound(with[2].heat(), with[2].heat_size(), 1), 0.0);
}

}  // namespace
}  // namespace tpr::index
