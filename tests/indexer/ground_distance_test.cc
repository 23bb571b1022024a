// Ground distance (Eq. 7), validation and preparation.
#include "indexer/lib/ground_distance.h"

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "gtest/gtest.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

using testing::SignatureGenerator;
using testing::SignatureGeneratorOptions;

// Eq. 7 straight from the raw features, with L2norm as documented:
// c_X ||X1 - X2||_2, the shorter vector padded with zeros.
double DirectEq7(const Feature& x, const Feature& y,
                 const GroundDistanceOptions& o) {
  auto l2 = [](const std::vector<double>& p, const std::vector<double>& q) {
    const size_t n = std::max(p.size(), q.size());
    double s = 0.0;
    for (size_t i = 0; i < n; ++i) {
      const double d = (i < p.size() ? p[i] : 0.0) - (i < q.size() ? q[i] : 0.0);
      s += d * d;
    }
    return std::sqrt(s);
  };
  return o.w1 * std::abs(x.integral_geodesic - y.integral_geodesic) + o.w2 * o.k_scale * l2(x.curvature, y.curvature) +
         o.w3 * o.a_scale * l2(x.area, y.area) + o.w4 * o.h_scale * l2(x.distance, y.distance);
}

PreparedSignature Prep(const Signature& s, const GroundDistanceOptions& o) {
  absl::StatusOr<PreparedSignature> p = Prepare(s, o);
  EXPECT_TRUE(p.ok()) << p.status();
  return *std::move(p);
}

Signature Valid() {
  Signature s;
  s.features.push_back({0.25, 0.1, {1, 2}, {0.5, 0.5}, {0.1, 0.1}});
  s.features.push_back({0.75, 0.9, {3, 4}, {0.2, 0.8}, {0.2, 0.3}});
  return s;
}

TEST(GroundDistanceTest, ValidSignatureAccepted) {
  EXPECT_TRUE(ValidateSignature(Valid()).ok());
}

TEST(GroundDistanceTest, InvalidSignaturesRejectedWithReason) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<std::pair<std::string, Signature>> cases;
  {
    Signature s;
    cases.push_back({"no feature", s});
  }
  {
    Signature s = Valid();
    s.features[0].weight = -0.25;
    s.features[1].weight = 1.25;
    cases.push_back({"must be finite and >= 0", s});
  }
  {
    Signature s = Valid();
    s.features[0].weight = nan;
    cases.push_back({"must be finite and >= 0", s});
  }
  {
    Signature s = Valid();
    s.features[0].weight = 0.3;
    cases.push_back({"sum to", s});
  }
  {
    Signature s = Valid();
    s.features[1].area.push_back(0.0);
    cases.push_back({"lengths", s});
  }
  {
    Signature s = Valid();
    s.features[1].curvature = {1, 2, 3};
    s.features[1].area = {1, 2, 3};
    s.features[1].distance = {1, 2, 3};
    cases.push_back({"lengths", s});
  }
  {
    Signature s = Valid();
    s.features[1].distance[0] = inf;
    cases.push_back({"non-finite", s});
  }
  {
    Signature s = Valid();
    s.features[0].integral_geodesic = nan;
    cases.push_back({"not finite", s});
  }
  {
    Signature s;
    for (int i = 0; i <= kMaxFeatures; ++i) {
      s.features.push_back({1.0 / (kMaxFeatures + 1), 0.5, {1}, {1}, {1}});
    }
    cases.push_back({"at most", s});
  }
  for (const auto& [what, s] : cases) {
    const absl::Status st = ValidateSignature(s);
    EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument) << what;
    EXPECT_NE(st.message().find(what), absl::string_view::npos)
        << "expected '" << what << "' in: " << st.message();
    EXPECT_EQ(Prepare(s, GroundDistanceOptions{}).status().code(),
              absl::StatusCode::kInvalidArgument);
  }
}

TEST(GroundDistanceTest, InvalidOptionsRejected) {
  GroundDistanceOptions o;
  o.w1 = 0.5;  // sum 1.25
  EXPECT_EQ(ValidateOptions(o).code(), absl::StatusCode::kInvalidArgument);
  o = GroundDistanceOptions{};
  o.w2 = -0.25;
  o.w1 = 0.75;
  EXPECT_EQ(ValidateOptions(o).code(), absl::StatusCode::kInvalidArgument);
  o = GroundDistanceOptions{};
  o.k_scale = 0.0;
  EXPECT_EQ(ValidateOptions(o).code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(Prepare(Valid(), o).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(ValidateOptions(GroundDistanceOptions{}).ok());
}

TEST(GroundDistanceTest, MatchesEquation7ComputedDirectly) {
  GroundDistanceOptions o;
  o.w1 = 0.1;
  o.w2 = 0.2;
  o.w3 = 0.3;
  o.w4 = 0.4;
  o.k_scale = 0.5;
  o.a_scale = 2.0;
  o.h_scale = 3.0;
  SignatureGenerator gen(SignatureGeneratorOptions{});
  for (int t = 0; t < 20; ++t) {
    const Signature sa = gen.Next();
    const Signature sb = gen.Next();
    const PreparedSignature a = Prep(sa, o);
    const PreparedSignature b = Prep(sb, o);
    for (int i = 0; i < a.size(); ++i) {
      for (int j = 0; j < b.size(); ++j) {
        const double expected = DirectEq7(sa.features[i], sb.features[j], o);
        EXPECT_NEAR(GroundDistance(a, i, b, j), expected, 1e-12 * expected);
      }
    }
  }
}

TEST(GroundDistanceTest, MatrixKernelMatchesScalarAndIsSymmetric) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  std::mt19937_64 rng(4);
  std::uniform_int_distribution<int> size(1, kMaxFeatures);
  for (int t = 0; t < 40; ++t) {
    const PreparedSignature a = Prep(
        t % 2 ? gen.Next() : gen.Random(size(rng)), GroundDistanceOptions{});
    const PreparedSignature b = Prep(
        t % 3 ? gen.Next() : gen.Random(size(rng)), GroundDistanceOptions{});
    std::vector<double> ab(static_cast<size_t>(a.size()) * b.stride());
    std::vector<double> ba(static_cast<size_t>(b.size()) * a.stride());
    GroundDistanceMatrix(a, b, ab.data(), b.stride());
    GroundDistanceMatrix(b, a, ba.data(), a.stride());
    for (int i = 0; i < a.size(); ++i) {
      for (int j = 0; j < b.size(); ++j) {
        const double m = ab[static_cast<size_t>(i) * b.stride() + j];
        EXPECT_NEAR(m, GroundDistance(a, i, b, j), 1e-14);
        EXPECT_EQ(m, ba[static_cast<size_t>(j) * a.stride() + i]);
      }
    }
  }
}

TEST(GroundDistanceTest, DifferentBandCountsComparedWithZeroPadding) {
  Signature sa = Valid();
  Signature sb;
  sb.features.push_back({1.0, 0.5, {1, 2, 3}, {0.3, 0.3, 0.4}, {0.1, 0, 0.2}});
  const GroundDistanceOptions o;
  const PreparedSignature a = Prep(sa, o);
  const PreparedSignature b = Prep(sb, o);
  std::vector<double> m(static_cast<size_t>(a.size()) * b.stride());
  GroundDistanceMatrix(a, b, m.data(), b.stride());
  for (int i = 0; i < a.size(); ++i) {
    const double expected = DirectEq7(sa.features[i], sb.features[0], o);
    EXPECT_NEAR(GroundDistance(a, i, b, 0), expected, 1e-14);
    EXPECT_NEAR(m[static_cast<size_t>(i) * b.stride()], expected, 1e-14);
  }
}

TEST(GroundDistanceTest, IsAMetricOnFeatures) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  const GroundDistanceOptions o;
  const PreparedSignature a = Prep(gen.Random(60), o);
  const PreparedSignature b = Prep(gen.Random(60), o);
  const PreparedSignature c = Prep(gen.Random(60), o);
  for (int i = 0; i < 60; ++i) {
    EXPECT_EQ(GroundDistance(a, i, a, i), 0.0);
    for (int j = 0; j < 60; ++j) {
      const double ab = GroundDistance(a, i, b, j);
      EXPECT_GT(ab, 0.0);
      EXPECT_EQ(ab, GroundDistance(b, j, a, i));
      for (int k = 0; k < 60; k += 7) {
        EXPECT_LE(ab, GroundDistance(a, i, c, k) + GroundDistance(c, k, b, j) +
                          1e-12);
      }
    }
  }
}

TEST(GroundDistanceTest, PreparedWeightsAndCentroid) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  Signature s = gen.Random(17);
  s.features[0].weight += 5e-7;  // within the 1e-6 tolerance: renormalized
  const PreparedSignature p = Prep(s, GroundDistanceOptions{});
  double sum = 0.0;
  for (int i = 0; i < p.size(); ++i) sum += p.weight(i);
  EXPECT_NEAR(sum, 1.0, 1e-15);
  EXPECT_EQ(p.size(), 17);
  EXPECT_EQ(p.bands(), 20);
  EXPECT_EQ(p.stride() % 8, 0);
  for (int r = 0; r < 1 + 3 * p.bands(); ++r) {
    double c = 0.0;
    for (int i = 0; i < p.size(); ++i) {
      c += p.weight(i) * p.coords()[static_cast<size_t>(r) * p.stride() + i];
    }
    EXPECT_NEAR(p.centroid()[r], c, 1e-15);
  }
  EXPECT_GT(p.MemoryBytes(), 0u);
}

}  // namespace
}  // namespace tpr::index
