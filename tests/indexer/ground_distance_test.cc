// Ground distance (Eq. 7), validation and preparation.
#include "indexer/lib/ground_distance.h"

#include <cmath>
#include <iostream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/internal/ground_distance_kernels.h"
#include "indexer/lib/internal/simd.h"
#include "tests/indexer/eq7_oracle.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

using testing::SignatureGenerator;
using testing::SignatureGeneratorOptions;

using testing::DirectEq7;
using testing::Float32Slack;

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
        EXPECT_NEAR(
            GroundDistance(a, i, b, j), expected,
            Float32Slack(sa.features[i], sb.features[j], o) + 1e-12 * expected);
      }
    }
  }
}

TEST(GroundDistanceTest, MatrixKernelMatchesScalarAndIsSymmetric) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  std::mt19937_64 rng(4);
  std::uniform_int_distribution<int> size(1, kMaxFeatures);
  for (int t = 0; t < 40; ++t) {
    const PreparedSignature a = Prep(t % 2 ? gen.Next() : gen.Random(size(rng)),
                                     GroundDistanceOptions{});
    const PreparedSignature b = Prep(t % 3 ? gen.Next() : gen.Random(size(rng)),
                                     GroundDistanceOptions{});
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
      // Padding columns (the masked tail of the float32 rows) stay finite:
      // the EMD's pricing pass reads them.
      for (int j = b.size(); j < b.stride(); ++j) {
        EXPECT_TRUE(std::isfinite(ab[static_cast<size_t>(i) * b.stride() + j]));
      }
    }
  }
}

// Every kernel variant this CPU runs (not only the one chosen at run
// time) agrees with the scalar GroundDistance, at every tail length of the
// masked float32 loads (sizes 1 .. 17 cover all 8 residues twice), and the
// wide ones with each other bit for bit. One test instance per variant;
// skipped, naming it, where this CPU cannot run it.
class MatrixKernelTest : public ::testing::TestWithParam<internal::SimdLevel> {
 protected:
  void SetUp() override {
    if (!internal::SimdLevelSupported(GetParam())) {
      GTEST_SKIP() << "this CPU cannot run the "
                   << internal::SimdLevelName(GetParam())
                   << " matrix kernels: not tested here";
    }
  }
};

TEST_P(MatrixKernelTest, MatchesScalarAndTheOtherWideVariant) {
  const internal::SimdLevel level = GetParam();
  // The other wide level, when this CPU runs it too.
  const internal::SimdLevel other = level == internal::SimdLevel::kAvx2
                                        ? internal::SimdLevel::kAvx512
                                        : internal::SimdLevel::kAvx2;
  const bool compare_other = level != internal::SimdLevel::kScalar &&
                             internal::SimdLevelSupported(other);
  SignatureGenerator gen(SignatureGeneratorOptions{});
  for (int na = 1; na <= 17; na += 4) {
    for (int nb = 1; nb <= 17; ++nb) {
      const PreparedSignature a = Prep(gen.Random(na), GroundDistanceOptions{});
      const PreparedSignature b = Prep(gen.Random(nb), GroundDistanceOptions{});
      std::vector<double> m(static_cast<size_t>(na) * b.stride(), -1.0);
      ASSERT_TRUE(
          internal::GroundDistanceMatrixAt(level, a, b, m.data(), b.stride()));
      std::vector<double> o(m.size(), -1.0);
      if (compare_other) {
        ASSERT_TRUE(internal::GroundDistanceMatrixAt(other, a, b, o.data(),
                                                     b.stride()));
      }
      for (int i = 0; i < na; ++i) {
        for (int j = 0; j < b.stride(); ++j) {
          const size_t k = static_cast<size_t>(i) * b.stride() + j;
          EXPECT_TRUE(std::isfinite(m[k]));
          if (j < nb) {
            EXPECT_NEAR(m[k], GroundDistance(a, i, b, j), 1e-14)
                << na << " x " << nb;
          }
          if (compare_other) {
            EXPECT_EQ(m[k], o[k]) << na << " x " << nb;
          }
        }
      }
    }
  }
  // Band counts that differ: the wide kernels refuse, nothing written.
  SignatureGeneratorOptions o7;
  o7.bands = 7;
  const PreparedSignature a =
      Prep(SignatureGenerator(o7).Random(3), GroundDistanceOptions{});
  const PreparedSignature b = Prep(gen.Random(3), GroundDistanceOptions{});
  std::vector<double> m(8 * 3, -1.0);
  EXPECT_EQ(internal::GroundDistanceMatrixAt(level, a, b, m.data(), 8),
            level == internal::SimdLevel::kScalar);
  if (level != internal::SimdLevel::kScalar) {
    EXPECT_EQ(m[0], -1.0);
  }
}

// The float32 matrix (GroundDistanceMatrix32) of each wide variant stays
// within its documented relative error of the double one, at every tail
// length of the masked loads (column sizes 1 .. 40), for several band
// counts, and equals the other wide variant's bit for bit; it is exactly
// 0 between a feature and itself; it refuses band counts that differ.
// The scalar level has no float32 kernel (and says so).
TEST_P(MatrixKernelTest, Float32MatrixWithinItsErrorBound) {
  const internal::SimdLevel level = GetParam();
  if (level == internal::SimdLevel::kScalar) {
    const PreparedSignature a =
        Prep(SignatureGenerator(SignatureGeneratorOptions{}).Random(3),
             GroundDistanceOptions{});
    std::vector<float> m(16 * 3, -1.0f);
    EXPECT_FALSE(internal::GroundDistanceMatrix32At(level, a, a, m.data(), 16));
    EXPECT_EQ(m[0], -1.0f);
    GTEST_SKIP() << "the scalar level has no float32 kernel (the double "
                    "matrix stands in for it)";
  }
  const internal::SimdLevel other = level == internal::SimdLevel::kAvx2
                                        ? internal::SimdLevel::kAvx512
                                        : internal::SimdLevel::kAvx2;
  const bool compare_other = internal::SimdLevelSupported(other);
  int checked = 0;
  double worst = 0.0;  // largest |error| / (theta c)
  for (int bands : {20, 7, 33}) {
    SignatureGeneratorOptions o;
    o.bands = bands;
    SignatureGenerator gen(o);
    const double theta = internal::Float32MatrixError(bands);
    for (int na : {1, 3, 4, 5, 17, 30}) {
      for (int nb = 1; nb <= 40; nb += (nb < 18 ? 1 : 7)) {
        const PreparedSignature a =
            Prep(gen.Random(na), GroundDistanceOptions{});
        const PreparedSignature b =
            Prep(gen.Random(nb), GroundDistanceOptions{});
        const int stride = internal::Stride32(b);
        ASSERT_EQ(stride % 16, 0);
        ASSERT_GE(stride, nb);
        std::vector<float> m(static_cast<size_t>(na) * stride, -1.0f);
        ASSERT_TRUE(
            internal::GroundDistanceMatrix32At(level, a, b, m.data(), stride));
        std::vector<float> om(m.size(), -1.0f);
        if (compare_other) {
          ASSERT_TRUE(internal::GroundDistanceMatrix32At(other, a, b, om.data(),
                                                         stride));
        }
        for (int i = 0; i < na; ++i) {
          for (int j = 0; j < stride; ++j) {
            const size_t k = static_cast<size_t>(i) * stride + j;
            const double got = m[k];
            ASSERT_TRUE(std::isfinite(got));
            if (compare_other) {
              EXPECT_EQ(m[k], om[k]) << bands << " bands, " << na << " x " << nb
                                     << " entry " << i << ", " << j;
            }
            if (j >= nb) continue;
            const double want = GroundDistance(a, i, b, j);
            EXPECT_LE(std::abs(got - want), (theta + 1e-15) * want)
                << bands << " bands, " << na << " x " << nb;
            worst = std::max(worst, std::abs(got - want) / (theta * want));
            ++checked;
          }
        }
        std::vector<float> self(static_cast<size_t>(na) *
                                internal::Stride32(a));
        ASSERT_TRUE(internal::GroundDistanceMatrix32At(level, a, a, self.data(),
                                                       internal::Stride32(a)));
        for (int i = 0; i < na; ++i) {
          EXPECT_EQ(self[static_cast<size_t>(i) * internal::Stride32(a) + i],
                    0.0f);
        }
      }
    }
  }
  EXPECT_GT(checked, 10000);
  EXPECT_GT(worst, 0.0);  // float32 rounding shows, and stays in the bound
  if (!compare_other) {
    std::cout << "not compared with " << internal::SimdLevelName(other)
              << ": this CPU cannot run it\n";
  }
  // Band counts that differ: refused, nothing written.
  SignatureGeneratorOptions o7;
  o7.bands = 7;
  const PreparedSignature a =
      Prep(SignatureGenerator(o7).Random(3), GroundDistanceOptions{});
  const PreparedSignature b =
      Prep(SignatureGenerator(SignatureGeneratorOptions{}).Random(3),
           GroundDistanceOptions{});
  std::vector<float> m(16 * 3, -1.0f);
  EXPECT_FALSE(internal::GroundDistanceMatrix32At(level, a, b, m.data(), 16));
  EXPECT_EQ(m[0], -1.0f);
}

INSTANTIATE_TEST_SUITE_P(
    Variants, MatrixKernelTest,
    ::testing::Values(internal::SimdLevel::kScalar, internal::SimdLevel::kAvx2,
                      internal::SimdLevel::kAvx512),
    [](const ::testing::TestParamInfo<internal::SimdLevel>& info) {
      return std::string(internal::SimdLevelName(info.param));
    });

// GroundDistanceMatrix32 runs the chosen level's kernel: none at the
// scalar level, the wide one's values otherwise.
TEST(GroundDistanceTest, Float32MatrixFollowsTheChosenLevel) {
  const PreparedSignature a =
      Prep(SignatureGenerator(SignatureGeneratorOptions{}).Random(5),
           GroundDistanceOptions{});
  std::vector<float> m(16 * 5, -1.0f), want(16 * 5, -1.0f);
  const internal::SimdLevel level = internal::ChosenSimdLevel();
  const bool ran = internal::GroundDistanceMatrix32(a, a, m.data(), 16);
  EXPECT_EQ(ran, level != internal::SimdLevel::kScalar)
      << internal::SimdLevelName(level);
  if (!ran) return;
  ASSERT_TRUE(internal::GroundDistanceMatrix32At(level, a, a, want.data(), 16));
  EXPECT_EQ(m, want);
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
    const double slack =
        Float32Slack(sa.features[i], sb.features[0], o) + 1e-14;
    EXPECT_NEAR(GroundDistance(a, i, b, 0), expected, slack);
    EXPECT_NEAR(m[static_cast<size_t>(i) * b.stride()], expected, slack);
  }
}

TEST(GroundDistanceTest, ValuesBeyondFloat32RangeRejected) {
  Signature s = Valid();
  s.features[1].distance[1] = 1e300;  // finite in double, infinite in float32
  absl::StatusOr<PreparedSignature> p = Prepare(s, GroundDistanceOptions{});
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(p.status().message().find("feature 1"), std::string::npos)
      << p.status();
  EXPECT_NE(p.status().message().find("float32"), std::string::npos)
      << p.status();
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
  const std::vector<double> centroid = Centroid(p);  // emd.h
  ASSERT_EQ(centroid.size(), static_cast<size_t>(p.rows()));
  for (int r = 0; r < 1 + 3 * p.bands(); ++r) {
    double c = 0.0;
    for (int i = 0; i < p.size(); ++i) {
      c += p.weight(i) * p.coords()[static_cast<size_t>(r) * p.size() + i];
    }
    EXPECT_NEAR(centroid[r], c, 1e-15);
  }
  EXPECT_GT(p.MemoryBytes(), 0u);
}

}  // namespace
}  // namespace tpr::index
