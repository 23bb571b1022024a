// Search machinery on signatures extracted from real meshes (the dev sets
// under $TPR_SHARED_DIR when present, generated shapes always), not only on
// drawn ones:
// - Compact storage (ground_distance.h): PreparedSignature keeps its
//   coordinates in float32. Every EMD stays within the documented bound of
//   the EMD on double coordinates (LEMON on Eq. 7 computed in double from
//   the raw features, eq7_oracle.h), and rankings do not change: wherever
//   two models' double distances to a query differ by more than their two
//   bounds, the float32 distances order them the same way. Also prints how
//   many top-10 lists are identical.
// - The lower-bound cascade (emd.h): the centroid bound (in double and from
//   the index's quantized CentroidTable) and the relaxed transport bounds
//   (the capacity one on the double and on the float32 matrix) never
//   exceed the exact EMD; with the spectral term on (generated shapes
//   with their spectra), the table's level-1 bound (centroid + spectral)
//   and the level-2 bound never exceed the exact distance of metric.h.
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <numeric>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "eval/lib/tpr_descriptor.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/synth/synth.h"
#include "gtest/gtest.h"
#include "indexer/lib/centroid_table.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/metric.h"
#include "tests/indexer/emd_oracle.h"
#include "tests/indexer/eq7_oracle.h"

namespace tpr::index {
namespace {

using testing::DirectEq7;
using testing::Float32EmdSlack;
using testing::LemonEmd;

extract::Options NoSpectrum() {
  extract::Options o;
  o.spectrum_eigenvalues = 0;  // the spectral embedding stays double anyway
  return o;
}

// Extracts the meshes of `paths` on two threads; failures are dropped
// (intake errors are other tests' business).
std::vector<Signature> ExtractFiles(const std::vector<std::string>& paths) {
  std::vector<Signature> out(paths.size());
  std::vector<char> ok(paths.size(), 0);
  auto work = [&](size_t first) {
    for (size_t i = first; i < paths.size(); i += 2) {
      absl::StatusOr<extract::LoadedMesh> mesh =
          extract::LoadMeshFromFile(paths[i], extract::IntakeOptions{});
      if (!mesh.ok()) continue;
      absl::StatusOr<extract::ExtractResult> r =
          extract::ExtractSignature(mesh->mesh, mesh->stats, NoSpectrum());
      if (!r.ok()) continue;
      out[i] = eval::ToIndexSignature(r->signature);
      ok[i] = 1;
    }
  };
  std::thread other(work, 1);
  work(0);
  other.join();
  std::vector<Signature> kept;
  for (size_t i = 0; i < out.size(); ++i) {
    if (ok[i]) kept.push_back(std::move(out[i]));
  }
  return kept;
}

// Every `stride`-th mesh of a "<path> <class>" manifest, or none when the
// manifest is absent.
std::vector<std::string> ManifestPaths(const std::string& dir, int stride) {
  std::ifstream manifest(dir + "/MANIFEST.txt");
  std::vector<std::string> paths;
  std::string line;
  for (int n = 0; std::getline(manifest, line); ++n) {
    std::istringstream in(line);
    std::string path;
    if (in >> path && n % stride == 0) paths.push_back(dir + "/" + path);
  }
  return paths;
}

struct Tally {
  int queries = 0;
  int identical_top10 = 0;
  int64_t pairs_checked = 0;
  int64_t bounds_checked = 0;
  double worst_error_over_bound = 0.0;
};

// Checks the bound and the ranking for up to `max_queries` queries (spread
// over the set) against every signature of the set.
Tally CheckSet(const std::vector<Signature>& set, int max_queries) {
  const GroundDistanceOptions ground;
  std::vector<PreparedSignature> prepared;
  for (const Signature& s : set) prepared.push_back(*Prepare(s, ground));
  const CentroidTable table = CentroidTable::Build(
      prepared.size(), [&](uint32_t i) { return &prepared[i]; });
  LemonEmd lemon;
  Tally tally;
  const size_t n = set.size();
  const size_t step = std::max<size_t>(1, n / static_cast<size_t>(max_queries));
  for (size_t q = 0; q < n; q += step) {
    const std::vector<double> qc = Centroid(prepared[q]);
    std::vector<double> d32(n), d64(n), slack(n);
    for (size_t j = 0; j < n; ++j) {
      std::vector<double> costs;
      for (const Feature& x : set[q].features) {
        for (const Feature& y : set[j].features)
          costs.push_back(DirectEq7(x, y, ground));
      }
      d64[j] = lemon.DistanceWithCosts(prepared[q], prepared[j], costs);
      d32[j] = Emd(prepared[q], prepared[j]);
      const double tolerance = d32[j] * 1e-12 + 1e-15;
      EXPECT_LE(EmdLowerBound(prepared[q], prepared[j]), d32[j] + tolerance);
      EXPECT_LE(table.LowerBound(qc.data(), prepared[q].bands(),
                                 static_cast<uint32_t>(j)),
                d32[j] + tolerance);
      EXPECT_LE(RelaxedTransportBound(prepared[q], prepared[j]),
                d32[j] + tolerance);
      EXPECT_LE(ConstrainedTransportBound(prepared[q], prepared[j]),
                d32[j] + tolerance);
      EXPECT_LE(ConstrainedTransportBound32(prepared[q], prepared[j]),
                d32[j] + tolerance);
      ++tally.bounds_checked;
      // The float32 bound plus LEMON's integer rounding (about 1e-12 of
      // the largest cost) and the solver's own tolerance.
      slack[j] = Float32EmdSlack(set[q], set[j], ground) +
                 1e-9 * std::max(d64[j], 1e-3);
      EXPECT_NEAR(d32[j], d64[j], slack[j]) << "query " << q << " model " << j;
      tally.worst_error_over_bound = std::max(
          tally.worst_error_over_bound,
          std::abs(d32[j] - d64[j]) / Float32EmdSlack(set[q], set[j], ground));
    }
    std::vector<size_t> by64(n);
    std::iota(by64.begin(), by64.end(), size_t{0});
    std::sort(by64.begin(), by64.end(), [&](size_t a, size_t b) {
      return d64[a] != d64[b] ? d64[a] < d64[b] : a < b;
    });
    for (size_t a = 0; a < n; ++a) {
      for (size_t b = a + 1; b < n; ++b) {
        const size_t x = by64[a];
        const size_t y = by64[b];
        if (d64[y] - d64[x] > slack[x] + slack[y]) {
          ++tally.pairs_checked;
          EXPECT_LT(d32[x], d32[y])
              << "query " << q << ": models " << x << ", " << y;
        }
      }
    }
    std::vector<size_t> by32 = by64;
    std::sort(by32.begin(), by32.end(), [&](size_t a, size_t b) {
      return d32[a] != d32[b] ? d32[a] < d32[b] : a < b;
    });
    const size_t top = std::min<size_t>(10, n);
    tally.identical_top10 +=
        std::equal(by32.begin(), by32.begin() + top, by64.begin());
    ++tally.queries;
  }
  return tally;
}

void Report(const char* name, size_t models, const Tally& t) {
  std::printf(
      "%s: %zu models, %d queries, %lld lower-bound pairs, %lld ordered pairs "
      "checked, top-10 identical in %d/%d, worst |EMD32 - EMD64| / bound "
      "%.3f\n",
      name, models, t.queries, static_cast<long long>(t.bounds_checked),
      static_cast<long long>(t.pairs_checked), t.identical_top10, t.queries,
      t.worst_error_over_bound);
  ::testing::Test::RecordProperty(
      std::string(name) + "_identical_top10",
      std::to_string(t.identical_top10) + "/" + std::to_string(t.queries));
}

// GeneratedShapes returns the signatures of every synthetic class x
// `poses` poses at 1500 vertices (always available), extracted with
// `options`; a failure is a test failure (and leaves the shape out).
std::vector<Signature> GeneratedShapes(int poses,
                                       const extract::Options& options) {
  std::vector<Signature> set;
  synth::ShapeOptions shape;
  shape.target_vertices = 1500;
  for (const std::string& cls : synth::ClassNames()) {
    for (int pose = 0; pose < poses; ++pose) {
      absl::StatusOr<extract::Mesh> mesh =
          synth::GenerateShape(cls, pose, shape);
      EXPECT_TRUE(mesh.ok()) << mesh.status();
      if (!mesh.ok()) continue;
      absl::StatusOr<extract::ExtractResult> r = extract::ExtractSignature(
          *mesh, extract::ComputeMeshStats(*mesh), options);
      EXPECT_TRUE(r.ok()) << r.status();
      if (r.ok()) set.push_back(eval::ToIndexSignature(r->signature));
    }
  }
  return set;
}

TEST(ExtractedSignaturesTest, GeneratedShapes) {
  // 10 synthetic classes x 4 poses.
  const std::vector<Signature> set = GeneratedShapes(4, NoSpectrum());
  ASSERT_EQ(set.size(), synth::ClassNames().size() * 4);
  const Tally t = CheckSet(set, 40);
  Report("generated", set.size(), t);
  EXPECT_GT(t.pairs_checked, 0);
}

TEST(ExtractedSignaturesTest, GeneratedShapesWithSpectraUnderTheDefaultMetric) {
  // 10 synthetic classes x 3 poses at 1500 vertices, extracted with their
  // spectra (the extractor's default eigenvalues), under every term (EMD +
  // spectral + heat trace): every bound of the index's cascade stays below
  // the exact distance, pair by pair.
  std::vector<PreparedSignature> set;
  for (const Signature& s : GeneratedShapes(3, extract::Options{})) {
    ASSERT_FALSE(s.spectrum.empty());
    set.push_back(*Prepare(s, GroundDistanceOptions{}));
  }
  ASSERT_EQ(set.size(), synth::ClassNames().size() * 3);
  const CentroidTable table =
      CentroidTable::Build(set.size(), [&](uint32_t i) { return &set[i]; });
  ASSERT_EQ(table.spectral_size(), set[0].spectral_size());
  int64_t spectral_positive = 0;
  for (size_t q = 0; q < set.size(); ++q) {
    const PreparedSignature& a = set[q];
    const std::vector<double> qc = Centroid(a);
    for (size_t j = 0; j < set.size(); ++j) {
      const PreparedSignature& b = set[j];
      const uint32_t slot = static_cast<uint32_t>(j);
      // EMD + S + H: each bound of the cascade plus the exact embeddings.
      const TermWeights all{1, 1, 1};
      const double d = Distance(a, b, all);
      const double tolerance = d * 1e-12 + 1e-15;
      const double spectral = SpectralDistance(a, b);
      const double heat = HeatDistance(a, b);
      const double table_spectral =
          table.SpectralLowerBound(a.spectral(), a.spectral_size(), slot);
      const double table_heat =
          table.HeatLowerBound(a.heat(), a.heat_size(), slot);
      EXPECT_LE(table_spectral, spectral) << q << " " << j;
      EXPECT_LE(table_heat, heat) << q << " " << j;
      const double level1 = table.LowerBound(qc.data(), a.bands(), slot) +
                            table_spectral + table_heat;
      EXPECT_LE(level1, DistanceLowerBound(a, b, all) + tolerance)
          << q << " " << j;
      EXPECT_LE(level1, d + tolerance) << q << " " << j;
      EXPECT_LE(ConstrainedTransportBound(a, b) + spectral + heat,
                d + tolerance)
          << q << " " << j;
      EXPECT_LE(ConstrainedTransportBound32(a, b) + spectral + heat,
                d + tolerance)
          << q << " " << j;
      spectral_positive += spectral > 0.0;
    }
  }
  // The spectra differ between shapes, so the spectral bound is exercised.
  EXPECT_GT(spectral_positive, static_cast<int64_t>(set.size() * 20));
}

TEST(ExtractedSignaturesTest, Shrec11Simplified) {
  const std::vector<std::string> paths = ManifestPaths(
      std::string(TPR_SHARED_DIR) + "/data/shrec11-simplified", 1);
  if (paths.empty())
    GTEST_SKIP() << "SHREC'11 simplified not found under " << TPR_SHARED_DIR;
  const std::vector<Signature> set = ExtractFiles(paths);
  ASSERT_GE(set.size(), paths.size() * 9 / 10);
  const Tally t = CheckSet(set, 40);
  Report("shrec11", set.size(), t);
  EXPECT_GT(t.pairs_checked, 0);
}

TEST(ExtractedSignaturesTest, Shrec07WatertightEveryFourth) {
  const std::vector<std::string> paths = ManifestPaths(
      std::string(TPR_SHARED_DIR) + "/data/shrec07-watertight", 4);
  if (paths.empty())
    GTEST_SKIP() << "SHREC'07 watertight not found under " << TPR_SHARED_DIR;
  const std::vector<Signature> set = ExtractFiles(paths);
  ASSERT_GE(set.size(), paths.size() * 9 / 10);
  const Tally t = CheckSet(set, 40);
  Report("shrec07", set.size(), t);
  EXPECT_GT(t.pairs_checked, 0);
}

}  // namespace
}  // namespace tpr::index
