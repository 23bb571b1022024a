// The distances the index searches with are metrics (section 6.2; Rubner
// et al. [22]; metric.h): identity, symmetry and the triangle inequality,
// for the EMD over Eq. 7 alone (the paper's distance) and for weightings
// of the EMD, the spectral and the heat-trace terms, on realistic
// generated signatures, on degenerate ones full of ties, and on signatures
// extracted from generated shapes; the embeddings against hand-computed
// values; the lower bounds the search relies on.
#include "indexer/lib/metric.h"

#include <algorithm>
#include <cmath>
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
#include "indexer/lib/spectral.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

constexpr double kTolerance = 1e-9;

// Options with the spectral term's transform t and the first 50 values,
// explicit, so that the hand-computed oracles do not follow the defaults.
GroundDistanceOptions WithSpectral(
    SpectralTransform t = SpectralTransform::kLog) {
  GroundDistanceOptions o;
  o.spectral.transform = t;
  o.spectral.eigenvalues = 50;
  return o;
}

// The paper's distance, and the EMD plus w times the spectral term.
constexpr TermWeights kPaper{1.0, 0.0, 0.0};
TermWeights EmdPlusSpectral(double w) { return {1.0, w, 0.0}; }

PreparedSignature Prep(const Signature& s,
                       const GroundDistanceOptions& o = {}) {
  absl::StatusOr<PreparedSignature> p = Prepare(s, o);
  EXPECT_TRUE(p.ok()) << p.status();
  return *std::move(p);
}

// Degenerate signatures: up to `max_features` features with coordinates
// on the grid {0, 1}, every fourth mass zero, and (when spectrum > 0) a
// spectrum of that length drawn from {1, 2}: ties and exact zeros
// everywhere.
std::vector<Signature> Degenerate(uint64_t seed, int count, int max_features,
                                  int spectrum) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> level(0, 1);
  std::uniform_int_distribution<int> size(1, max_features);
  std::vector<Signature> out;
  for (int m = 0; m < count; ++m) {
    Signature sig;
    const int n = size(rng);
    for (int i = 0; i < n; ++i) {
      Feature f;
      f.weight = (i % 4 == 3) ? 0.0 : 1.0;
      f.integral_geodesic = level(rng);
      // assign(count, value): GCC 12 misreads a one-element initializer
      // list here (-Wnonnull false positive).
      f.curvature.assign(1, 1.0 * level(rng));
      f.area.assign(1, 1.0 * level(rng));
      f.distance.assign(1, 1.0 * level(rng));
      sig.features.push_back(f);
    }
    double sum = 0.0;
    for (const Feature& f : sig.features) sum += f.weight;
    for (Feature& f : sig.features) f.weight /= sum;
    for (int i = 0; i < spectrum; ++i) sig.spectrum.push_back(1.0 + level(rng));
    std::sort(sig.spectrum.begin(), sig.spectrum.end());
    out.push_back(std::move(sig));
  }
  return out;
}

// Checks the three axioms on every triple of `sigs` (at most `max_triples`
// random ones) and returns the number of triples checked.
int CheckMetric(const std::vector<PreparedSignature>& sigs, int max_triples,
                uint64_t seed, const TermWeights& w = kPaper) {
  EmdSolver solver;
  const int n = static_cast<int>(sigs.size());
  std::vector<double> d(static_cast<size_t>(n) * n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      d[static_cast<size_t>(i) * n + j] = Distance(solver, sigs[i], sigs[j], w);
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

TEST(MetricTest, CombinedIsAMetricOnGeneratedSignaturesWithSpectra) {
  for (SpectralTransform t :
       {SpectralTransform::kRaw, SpectralTransform::kByIndex,
        SpectralTransform::kLog}) {
    testing::SignatureGeneratorOptions o;
    o.seed = 91;
    o.classes = 6;
    o.jitter = 0.02;
    o.spectrum = 50;
    testing::SignatureGenerator gen(o);
    std::vector<PreparedSignature> sigs;
    std::mt19937_64 rng(92);
    std::uniform_int_distribution<int> length(0, 60);  // short, empty, long
    for (int i = 0; i < 60; ++i) {
      Signature s = gen.Next();
      if (i % 5 == 4) {
        const size_t len = static_cast<size_t>(length(rng));
        std::vector<double> spectrum;
        for (size_t k = 0; k < len; ++k) {
          spectrum.push_back(k < s.spectrum.size() ? s.spectrum[k] : 1.0 + k);
        }
        std::sort(spectrum.begin(), spectrum.end());
        s.spectrum = spectrum;
      }
      sigs.push_back(Prep(s, WithSpectral(t)));
    }
    EXPECT_EQ(CheckMetric(sigs, 20000, 93, EmdPlusSpectral(0.7)), 20000)
        << SpectralTransformName(t);
    // Every term, and the embeddings alone (no EMD computed).
    EXPECT_EQ(CheckMetric(sigs, 5000, 94, {0.5, 1.0, 2.0}), 5000);
    EXPECT_EQ(CheckMetric(sigs, 5000, 95, {0.0, 1.0, 3.0}), 5000);
  }
}

TEST(MetricTest, CombinedIsAMetricOnDegenerateSignaturesAndSpectra) {
  // EMD ties, spectral ties and exact zeros everywhere.
  GroundDistanceOptions o = WithSpectral(SpectralTransform::kByIndex);
  o.spectral.eigenvalues = 3;
  o.heat.eigenvalues = 3;
  std::vector<PreparedSignature> sigs;
  for (const Signature& s : Degenerate(15, 80, 6, 3))
    sigs.push_back(Prep(s, o));
  EXPECT_EQ(CheckMetric(sigs, 5000, 16, EmdPlusSpectral(0.5)), 5000);
  EXPECT_EQ(CheckMetric(sigs, 5000, 17, {0.3, 0.0, 1.5}), 5000);
}

TEST(MetricTest, EmbeddingMatchesHandComputedValues) {
  const std::vector<double> sphere = {2, 2, 2, 6};  // l (l + 1), unit sphere
  SpectralOptions o;
  o.eigenvalues = 6;  // two past the spectrum: padded with s_i = i
  const double c = 1.0 / std::sqrt(6.0);
  o.transform = SpectralTransform::kRaw;
  std::vector<double> e = SpectralEmbedding(sphere, o);
  const std::vector<double> raw = {2, 2, 2, 6, 5, 6};
  ASSERT_EQ(e.size(), 6u);
  for (int i = 0; i < 6; ++i) EXPECT_DOUBLE_EQ(e[i], c * raw[i]) << i;
  o.transform = SpectralTransform::kByIndex;
  e = SpectralEmbedding(sphere, o);
  const std::vector<double> by_index = {2, 1, 2.0 / 3, 1.5, 1, 1};
  for (int i = 0; i < 6; ++i) EXPECT_DOUBLE_EQ(e[i], c * by_index[i]) << i;
  o.transform = SpectralTransform::kLog;
  e = SpectralEmbedding(sphere, o);
  for (int i = 0; i < 6; ++i) EXPECT_DOUBLE_EQ(e[i], c * std::log(raw[i])) << i;
  // Values past n are ignored.
  o.eigenvalues = 2;
  EXPECT_EQ(SpectralEmbedding(sphere, o).size(), 2u);
  // The distance is the Euclidean one: |(3, 4)| = 5.
  const double a[2] = {1, 1}, b[2] = {4, 5};
  EXPECT_DOUBLE_EQ(SpectralDistance(a, b, 2), 5.0);
}

// The heat trace of the unit sphere's spectrum s = (2, 2, 2, 6) padded to
// n = 6 with s_5 = 5, s_6 = 6, at m = 2 times 0.1 and 1: F_j = log(t_j
// Z(t_j)) / sqrt(2), written out by hand.
TEST(MetricTest, HeatTraceMatchesHandComputedValues) {
  const std::vector<double> sphere = {2, 2, 2, 6};
  HeatTraceOptions o;
  o.scales = 2;
  o.t_min = 0.1;
  o.t_max = 1.0;
  o.eigenvalues = 6;
  const std::vector<double> f = HeatTraceEmbedding(sphere, o);
  ASSERT_EQ(f.size(), 2u);
  for (int j = 0; j < 2; ++j) {
    const double t = j == 0 ? 0.1 : 1.0;
    const double z = 3 * std::exp(-2 * t) + std::exp(-6 * t) +
                     std::exp(-5 * t) + std::exp(-6 * t);
    EXPECT_NEAR(f[j], std::log(t * z) / std::sqrt(2.0), 1e-14) << j;
  }
  o.scales = 0;
  EXPECT_TRUE(HeatTraceEmbedding(sphere, o).empty());
}

TEST(MetricTest, DistanceIsTheWeightedSumAndTheEmdAloneIsThePaper) {
  testing::SignatureGeneratorOptions go;
  go.seed = 5;
  go.spectrum = 50;
  testing::SignatureGenerator gen(go);
  const GroundDistanceOptions o = WithSpectral();
  for (int n = 0; n < 20; ++n) {
    const Signature x = gen.Next(), y = gen.Next();
    const PreparedSignature a = Prep(x, o), b = Prep(y, o);
    EXPECT_EQ(a.spectral_size(), 50);
    EXPECT_EQ(a.heat_size(), o.heat.scales);
    // The paper's weighting: exactly the EMD of Eq. 7, bit for bit.
    EXPECT_EQ(Distance(a, b, kPaper), Emd(a, b));
    EXPECT_EQ(DistanceLowerBound(a, b, kPaper), EmdLowerBound(a, b));
    // The spectral term against its hand-computed value.
    double s = 0.0;
    for (int i = 0; i < 50; ++i) {
      const double d = std::log(x.spectrum[i]) - std::log(y.spectrum[i]);
      s += d * d;
    }
    const double spectral = std::sqrt(s / 50.0);
    const std::vector<double> hx = HeatTraceEmbedding(x.spectrum, o.heat);
    const std::vector<double> hy = HeatTraceEmbedding(y.spectrum, o.heat);
    const double heat = SpectralDistance(hx.data(), hy.data(), hx.size());
    // The stored embeddings are float32 (ground_distance.h): each value
    // moves by at most 2^-24 of itself, so a term by at most
    // 2^-24 (||E(x)|| + ||E(y)||).
    auto rounding = [](const std::vector<double>& ex,
                       const std::vector<double>& ey) {
      const std::vector<double> zero(ex.size(), 0.0);
      return std::ldexp(SpectralDistance(ex.data(), zero.data(), ex.size()) +
                            SpectralDistance(ey.data(), zero.data(), ey.size()),
                        -24) +
             1e-12;
    };
    const double rs = rounding(SpectralEmbedding(x.spectrum, o.spectral),
                               SpectralEmbedding(y.spectrum, o.spectral));
    const double rh = rounding(hx, hy);
    EXPECT_NEAR(SpectralDistance(a, b), spectral, rs);
    EXPECT_NEAR(HeatDistance(a, b), heat, rh);
    const TermWeights w{0.8, 1.5, 2.5};
    EXPECT_NEAR(Distance(a, b, w),
                0.8 * Emd(a, b) + 1.5 * spectral + 2.5 * heat,
                1.5 * rs + 2.5 * rh + 1e-12);
    // A term of weight 0 is left out exactly (no EMD for {0, 1, 0}).
    EXPECT_EQ(Distance(a, b, {0, 1, 0}), SpectralDistance(a, b));
    EXPECT_EQ(Distance(a, b, {0, 0, 1}), HeatDistance(a, b));
    // The bounds the search uses: embeddings <= bound <= d_w.
    EXPECT_LE(1.5 * SpectralDistance(a, b) + 2.5 * HeatDistance(a, b),
              DistanceLowerBound(a, b, w));
    EXPECT_LE(DistanceLowerBound(a, b, w), Distance(a, b, w) + kTolerance);
  }
}

TEST(MetricTest, SpectralTermSeparatesOnlyWhatTheEmdConfuses) {
  // Identity of indiscernibles (metric.h): equal features, different
  // spectra are at distance S > 0 when S is weighed and 0 under the paper's
  // distance; spectra that agree on the first n values are at 0 either way.
  testing::SignatureGeneratorOptions go;
  go.spectrum = 8;
  testing::SignatureGenerator gen(go);
  Signature x = gen.Next();
  Signature y = x;
  y.spectrum[3] *= 1.5;
  std::sort(y.spectrum.begin(), y.spectrum.end());
  GroundDistanceOptions o = WithSpectral();
  EXPECT_EQ(Distance(Prep(x, o), Prep(y, o), kPaper), 0.0);
  EXPECT_GT(Distance(Prep(x, o), Prep(y, o), EmdPlusSpectral(1.0)), 0.0);
  EXPECT_GT(Distance(Prep(x, o), Prep(y, o), {1, 0, 1}), 0.0);
  Signature z = x;
  z.spectrum.push_back(1e6);  // past n = 8
  o.spectral.eigenvalues = 8;
  o.heat.eigenvalues = 8;
  EXPECT_EQ(Distance(Prep(x, o), Prep(z, o), {1, 1, 1}), 0.0);
}

TEST(MetricTest, EmdIsAMetricOnDegenerateSignatures) {
  // Coarse-grid coordinates and zero masses: ties everywhere.
  std::vector<PreparedSignature> sigs;
  for (const Signature& s : Degenerate(5, 40, 12, 0)) sigs.push_back(Prep(s));
  EXPECT_EQ(CheckMetric(sigs, 5000, 6), 5000);
}

TEST(MetricTest, EmdIsAMetricOnExtractedSignatures) {
  const std::vector<std::string> classes = synth::ClassNames();
  synth::ShapeOptions shape;
  shape.target_vertices = 2000;
  std::vector<PreparedSignature> sigs;
  std::vector<Signature> raw;
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
      raw.push_back(s);
    }
  }
  EXPECT_EQ(CheckMetric(sigs, 2000, 3), 2000);
  // And with the spectral term on the extracted spectra (whatever the
  // extractor gives; empty spectra see the Weyl padding).
  std::vector<PreparedSignature> combined;
  for (const Signature& s : raw) combined.push_back(Prep(s, WithSpectral()));
  EXPECT_EQ(CheckMetric(combined, 2000, 4, EmdPlusSpectral(0.5)), 2000);
  for (Intent intent : {Intent::kBalanced, Intent::kIdentity, Intent::kKind}) {
    EXPECT_EQ(CheckMetric(combined, 1000, 5, IntentWeights(intent)), 1000)
        << IntentName(intent);
  }
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
