// The kernel variants (indexer/lib/internal/simd.h, emd_kernels.h): the
// run-time choice and TPR_SIMD, and every EMD kernel of every variant this
// CPU runs against the scalar one, bit for bit. A variant the CPU cannot
// run is reported as a skipped test naming it. The ground-distance
// matrices' variants are checked in ground_distance_test.cc.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <limits>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "indexer/lib/internal/emd_kernels.h"
#include "indexer/lib/internal/simd.h"

namespace tpr::index::internal {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(SimdTest, NamesParseBackAndUnknownNamesAreRefused) {
  for (SimdLevel level : kSimdLevels) {
    absl::StatusOr<SimdLevel> parsed = ParseSimdLevel(SimdLevelName(level));
    ASSERT_TRUE(parsed.ok()) << parsed.status();
    EXPECT_EQ(*parsed, level);
  }
  EXPECT_STREQ(SimdLevelName(SimdLevel::kAvx2), "avx2");
  const absl::StatusOr<SimdLevel> bad = ParseSimdLevel("avx3");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("\"avx3\""), absl::string_view::npos)
      << bad.status();
}

// TPR_SIMD caps the level, never raises it past what the CPU runs.
TEST(SimdTest, EnvironmentCapsTheLevel) {
  const SimdLevel hi = SimdLevel::kAvx512;
  EXPECT_EQ(*CappedSimdLevel(nullptr, hi), hi);
  EXPECT_EQ(*CappedSimdLevel("", hi), hi);
  EXPECT_EQ(*CappedSimdLevel("avx2", hi), SimdLevel::kAvx2);
  EXPECT_EQ(*CappedSimdLevel("scalar", hi), SimdLevel::kScalar);
  EXPECT_EQ(*CappedSimdLevel("avx512", SimdLevel::kAvx2), SimdLevel::kAvx2);
  EXPECT_EQ(*CappedSimdLevel("avx2", SimdLevel::kScalar), SimdLevel::kScalar);
  EXPECT_FALSE(CappedSimdLevel("AVX2", hi).ok());
  // This process's choice follows its own environment.
  absl::StatusOr<SimdLevel> expected =
      CappedSimdLevel(std::getenv("TPR_SIMD"), HighestSimdLevel());
  EXPECT_EQ(ChosenSimdLevel(), expected.ok() ? *expected : HighestSimdLevel());
  std::cout << "kernel variant of this run: "
            << SimdLevelName(ChosenSimdLevel()) << "\n";
}

// CpuFlags returns the feature flags the kernel lists in /proc/cpuinfo (an
// oracle independent of the compiler's CPU query), empty where there is none.
std::set<std::string> CpuFlags() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("flags", 0) != 0) continue;
    std::istringstream words(line.substr(line.find(':') + 1));
    std::set<std::string> flags;
    for (std::string w; words >> w;) flags.insert(w);
    return flags;
  }
  return {};
}

// SimdLevelSupported is the one CPU-feature check: it agrees with the
// CPU's flags, and HighestSimdLevel is the highest level it accepts.
TEST(SimdTest, SupportedLevelsMatchCpuFlags) {
  EXPECT_TRUE(SimdLevelSupported(SimdLevel::kScalar));
  EXPECT_FALSE(SimdLevelSupported(static_cast<SimdLevel>(3)));
  SimdLevel highest = SimdLevel::kScalar;
  for (SimdLevel level : kSimdLevels) {
    if (SimdLevelSupported(level)) highest = level;
    EXPECT_EQ(EmdKernelsFor(level) != nullptr, SimdLevelSupported(level))
        << SimdLevelName(level);
  }
  EXPECT_EQ(HighestSimdLevel(), highest);
#if defined(__GNUC__) && defined(__x86_64__)
  const std::set<std::string> flags = CpuFlags();
  if (flags.empty()) GTEST_SKIP() << "no flags line in /proc/cpuinfo";
  EXPECT_EQ(SimdLevelSupported(SimdLevel::kAvx2),
            flags.count("avx2") == 1 && flags.count("fma") == 1 &&
                flags.count("popcnt") == 1);
  EXPECT_EQ(SimdLevelSupported(SimdLevel::kAvx512),
            flags.count("avx512f") == 1 && flags.count("popcnt") == 1);
#else
  EXPECT_FALSE(SimdLevelSupported(SimdLevel::kAvx2));
  EXPECT_FALSE(SimdLevelSupported(SimdLevel::kAvx512));
#endif
}

// Every wide variant against the scalar kernels, one test instance per
// variant; skipped, naming it, where this CPU cannot run it.
class EmdKernelsTest : public ::testing::TestWithParam<SimdLevel> {
 protected:
  void SetUp() override {
    if (!SimdLevelSupported(GetParam())) {
      GTEST_SKIP() << "this CPU cannot run the " << SimdLevelName(GetParam())
                   << " kernels: not tested here";
    }
    wide_ = EmdKernelsFor(GetParam());
    scalar_ = EmdKernelsFor(SimdLevel::kScalar);
    ASSERT_NE(wide_, nullptr);
    ASSERT_NE(scalar_, nullptr);
  }
  // A value on a coarse grid half the time (ties), else continuous.
  double Value(double lo, double hi) {
    std::uniform_real_distribution<double> u(lo, hi);
    const double x = u(rng_);
    return (rng_() & 1) ? std::round(x * 4.0) / 4.0 : x;
  }
  static int Stride(int m) { return (m + 7) / 8 * 8; }

  const EmdKernels* wide_ = nullptr;
  const EmdKernels* scalar_ = nullptr;
  std::mt19937_64 rng_{27};
};

TEST_P(EmdKernelsTest, CollectMatchesScalar) {
  int found = 0;
  for (int t = 0; t < 400; ++t) {
    const int n = 1 + static_cast<int>(rng_() % 70);
    const int m = 1 + static_cast<int>(rng_() % 200);
    const int cs = Stride(m);
    std::vector<double> cost(static_cast<size_t>(n) * cs);
    for (double& c : cost) c = Value(0.0, 2.0);
    std::vector<double> u(n), v(cs, -kInf);
    for (double& x : u) x = Value(-1.0, 1.0);
    for (int j = 0; j < m; ++j) v[j] = Value(-1.0, 3.0);
    const double tol = (t % 3 == 0) ? 0.0 : 1e-12;
    std::vector<int> ci(cs, -7), cj(cs, -7), wi(cs, -7), wj(cs, -7);
    const int count = scalar_->collect(cost.data(), cs, n, u.data(), v.data(),
                                       tol, ci.data(), cj.data());
    ASSERT_EQ(wide_->collect(cost.data(), cs, n, u.data(), v.data(), tol,
                             wi.data(), wj.data()),
              count)
        << n << " x " << m;
    for (int c = 0; c < count; ++c) {
      EXPECT_EQ(wi[c], ci[c]) << n << " x " << m << " candidate " << c;
      EXPECT_EQ(wj[c], cj[c]) << n << " x " << m << " candidate " << c;
    }
    found += count;
  }
  EXPECT_GT(found, 1000);  // the cases have candidates to compare
}

TEST_P(EmdKernelsTest, RowArgMinMatchesScalar) {
  for (int t = 0; t < 3000; ++t) {
    const int m = 1 + static_cast<int>(rng_() % 200);
    const int cs = Stride(m);
    std::vector<double> row(cs), offset(cs);
    for (double& x : row) x = Value(0.0, 2.0);
    for (double& x : offset) x = Value(-1.0, 0.0);
    std::vector<uint64_t> closed((cs + 63) / 64, 0);
    const int shut_permille = static_cast<int>(rng_() % 1000);
    for (int j = 0; j < cs; ++j) {
      const bool shut =
          j >= m || static_cast<int>(rng_() % 1000) < shut_permille;
      closed[j >> 6] |= static_cast<uint64_t>(shut) << (j & 63);
    }
    const int open = static_cast<int>(rng_() % m);  // at least one
    closed[open >> 6] &= ~(uint64_t{1} << (open & 63));
    const uint64_t lo = closed[0];
    if (rng_() & 1) closed[0] = ~uint64_t{0};  // closed[0] is not read
    EXPECT_EQ(
        wide_->row_arg_min(row.data(), offset.data(), lo, closed.data(), cs),
        scalar_->row_arg_min(row.data(), offset.data(), lo, closed.data(), cs))
        << "m " << m << " case " << t;
  }
}

TEST_P(EmdKernelsTest, ColumnMinMatchesScalar) {
  for (int t = 0; t < 300; ++t) {
    const int n = 1 + static_cast<int>(rng_() % 70);
    const int cs = Stride(1 + static_cast<int>(rng_() % 200));
    std::vector<double> cost(static_cast<size_t>(n) * cs);
    for (double& c : cost) c = Value(-1.0, 2.0);
    std::vector<double> want(cs, -1.0), got(cs, -2.0);
    scalar_->column_min(cost.data(), cs, n, want.data());
    wide_->column_min(cost.data(), cs, n, got.data());
    for (int j = 0; j < cs; ++j) EXPECT_EQ(got[j], want[j]) << n << " " << j;
  }
}

TEST_P(EmdKernelsTest, RankOrderMatchesScalar) {
  for (int t = 0; t < 500; ++t) {
    const int n = 1 + static_cast<int>(rng_() % 200);
    std::vector<double> w(n);
    for (double& x : w) x = (t % 4 == 0) ? 0.0 : Value(0.0, 0.1);
    std::vector<int> want(n, -1), got(n, -2);
    scalar_->rank_order(w.data(), n, want.data());
    wide_->rank_order(w.data(), n, got.data());
    EXPECT_EQ(got, want) << "n " << n;
  }
}

INSTANTIATE_TEST_SUITE_P(Variants, EmdKernelsTest,
                         ::testing::Values(SimdLevel::kAvx2,
                                           SimdLevel::kAvx512),
                         [](const ::testing::TestParamInfo<SimdLevel>& info) {
                           return std::string(SimdLevelName(info.param));
                         });

}  // namespace
}  // namespace tpr::index::internal
