// The EMD over Eq. 7 is a metric (section 6.2; Rubner et al. [22]):
// identity, symmetry and the triangle inequality, on realistic generated
// signatures and on signatures extracted from generated shapes.
#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "eval/lib/tpr_descriptor.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh.h"
#include "extractor/synth/synth.h"
#include "gtest/gtest.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

constexpr double kTolerance = 1e-9;

PreparedSignature Prep(const Signature& s) {
  absl::StatusOr<PreparedSignature> p = Prepare(s, GroundDistanceOptions{});
  EXPECT_TRUE(p.ok()) << p.status();
  return *std::move(p);
}

// Checks the three axioms on every triple of `sigs` (at most `max_triples`
// random ones) and returns the number of triples checked.
int CheckMetric(const std::vector<PreparedSignature>& sigs, int max_triples,
                uint64_t seed) {
  EmdSolver solver;
  const int n = static_cast<int>(sigs.size());
  std::vector<double> d(static_cast<size_t>(n) * n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      d[static_cast<size_t>(i) * n + j] = solver.Distance(sigs[i], sigs[j]);
    }
  }
  auto at = [&](int i, int j) { return d[static_cast<size_t>(i) * n + j]; };
  for (int i = 0; i < n; ++i) {
    EXPECT_NEAR(at(i, i), 0.0, kTolerance) << i;
    for (int j = 0; j < n; ++j) {
      EXPECT_GE(at(i, j), 0.0);
      EXPECT_NEAR(at(i, j), at(j, i), kTolerance) << i << " " << j;
    }
  }
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pick(0, n - 1);
  int checked = 0;
  for (int t = 0; t < max_triples; ++t) {
    const int a = pick(rng);
    const int b = pick(rng);
    const int c = pick(rng);
    EXPECT_LE(at(a, c), at(a, b) + at(b, c) + kTolerance)
        << a << " " << b << " " << c;
    ++checked;
  }
  // Every triple's tightest form: d(a, c) <= min_b d(a, b) + d(b, c).
  for (int a = 0; a < n; ++a) {
    for (int c = 0; c < n; ++c) {
      double best = 1e300;
      for (int b = 0; b < n; ++b) best = std::min(best, at(a, b) + at(b, c));
      EXPECT_LE(at(a, c), best + kTolerance) << a << " " << c;
    }
  }
  return checked;
}

TEST(MetricTest, EmdIsAMetricOnGeneratedSignatures) {
  testing::SignatureGeneratorOptions o;
  o.seed = 77;
  o.classes = 6;
  o.jitter = 0.02;  // tight classes: many small distances, close to ties
  testing::SignatureGenerator gen(o);
  std::vector<PreparedSignature> sigs;
  for (int i = 0; i < 60; ++i) sigs.push_back(Prep(gen.Next()));
  std::mt19937_64 rng(78);
  std::uniform_int_distribution<int> size(1, 40);
  for (int i = 0; i < 20; ++i) sigs.push_back(Prep(gen.Random(size(rng))));
  EXPECT_EQ(CheckMetric(sigs, 20000, 79), 20000);
}

TEST(MetricTest, EmdIsAMetricOnDegenerateSignatures) {
  // Coarse-grid coordinates and zero masses: ties everywhere.
  std::mt19937_64 rng(5);
  std::uniform_int_distribution<int> level(0, 1);
  std::uniform_int_distribution<int> size(1, 12);
  std::vector<PreparedSignature> sigs;
  for (int s = 0; s < 40; ++s) {
    Signature sig;
    const int n = size(rng);
    for (int i = 0; i < n; ++i) {
      Feature f;
      f.weight = (i % 4 == 3) ? 0.0 : 1.0;
      f.integral_geodesic = level(rng);
      f.curvature = {1.0 * level(rng)};
      f.area = {1.0 * level(rng)};
      f.distance = {1.0 * level(rng)};
      sig.features.push_back(f);
    }
    double sum = 0.0;
    for (const Feature& f : sig.features) sum += f.weight;
    for (Feature& f : sig.features) f.weight /= sum;
    sigs.push_back(Prep(sig));
  }
  EXPECT_EQ(CheckMetric(sigs, 5000, 6), 5000);
}

TEST(MetricTest, EmdIsAMetricOnExtractedSignatures) {
  const std::vector<std::string> classes = synth::ClassNames();
  synth::ShapeOptions shape;
  shape.target_vertices = 2000;
  std::vector<PreparedSignature> sigs;
  for (size_t c = 0; c < std::min<size_t>(classes.size(), 4); ++c) {
    for (int pose = 0; pose < 3; ++pose) {
      absl::StatusOr<extract::Mesh> mesh =
          synth::GenerateShape(classes[c], pose, shape);
      ASSERT_TRUE(mesh.ok()) << mesh.status();
      const extract::MeshStats stats = extract::ComputeMeshStats(*mesh);
      absl::StatusOr<extract::ExtractResult> r =
          extract::ExtractSignature(*mesh, stats, extract::Options{});
      ASSERT_TRUE(r.ok()) << classes[c] << " pose " << pose << ": "
                          << r.status();
      const Signature s = eval::ToIndexSignature(r->signature);
      ASSERT_TRUE(ValidateSignature(s).ok())
          << classes[c] << ": " << ValidateSignature(s);
      sigs.push_back(Prep(s));
    }
  }
  EXPECT_EQ(CheckMetric(sigs, 2000, 3), 2000);
  // Same class, other pose should usually be nearer than another class;
  // not asserted here (retrieval quality is the extractor's test), but the
  // lower bound must hold on real data.
  for (const PreparedSignature& a : sigs) {
    for (const PreparedSignature& b : sigs) {
      EXPECT_LE(EmdLowerBound(a, b), Emd(a, b) + kTolerance);
    }
  }
}

}  // namespace
}  // namespace tpr::index
