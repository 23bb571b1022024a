// EMD (section 6.1): exactness against LEMON and a brute-force oracle,
// degenerate inputs, the centroid lower bound, allocation and threads.
#include "indexer/lib/emd.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <new>
#include <random>
#include <thread>
#include <vector>

#include "gtest/gtest.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/internal/ground_distance_kernels.h"
#include "tests/allocation_counter.h"
#include "tests/indexer/emd_oracle.h"
#include "tests/indexer/eq7_oracle.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

using testing::DirectEq7;
using testing::Float32EmdSlack;
using testing::LemonEmd;
using testing::SignatureGenerator;
using testing::SignatureGeneratorOptions;

PreparedSignature Prep(const Signature& s,
                       const GroundDistanceOptions& o = {}) {
  absl::StatusOr<PreparedSignature> p = Prepare(s, o);
  EXPECT_TRUE(p.ok()) << p.status();
  return *std::move(p);
}

void ExpectRelNear(double actual, double expected, double rel) {
  EXPECT_NEAR(actual, expected, rel * std::max(std::abs(expected), 1e-12))
      << "actual " << actual << " expected " << expected;
}

// Brute force: the optimum of a transportation LP is attained at a basic
// solution, i.e. a spanning tree of n + m - 1 cells of the bipartite graph.
// Enumerate every subset of n + m - 1 cells, keep those forming a tree,
// solve its unique flow by peeling leaves, keep the non-negative ones, take
// the cheapest. Exponential: only for n, m <= 3.
double BruteForceEmd(const std::vector<double>& wa,
                     const std::vector<double>& wb,
                     const std::vector<std::vector<double>>& cost) {
  const int n = static_cast<int>(wa.size());
  const int m = static_cast<int>(wb.size());
  const int cells = n * m;
  const int k = n + m - 1;
  double best = 1e300;
  for (int mask = 0; mask < (1 << cells); ++mask) {
    if (__builtin_popcount(static_cast<unsigned>(mask)) != k) continue;
    std::vector<int> ci;
    std::vector<int> cj;
    for (int c = 0; c < cells; ++c) {
      if (mask & (1 << c)) {
        ci.push_back(c / m);
        cj.push_back(c % m);
      }
    }
    std::vector<double> rest(wa);
    rest.insert(rest.end(), wb.begin(), wb.end());
    std::vector<double> f(static_cast<size_t>(k), 0.0);
    std::vector<bool> used(static_cast<size_t>(k), false);
    bool ok = true;
    for (int step = 0; step < k && ok; ++step) {
      // A node with exactly one unused incident cell is a leaf.
      int leaf_cell = -1;
      int leaf_node = -1;
      for (int v = 0; v < n + m && leaf_cell < 0; ++v) {
        int count = 0;
        int last = -1;
        for (int c = 0; c < k; ++c) {
          if (!used[c] && (ci[c] == v || n + cj[c] == v)) {
            ++count;
            last = c;
          }
        }
        if (count == 1) {
          leaf_cell = last;
          leaf_node = v;
        }
      }
      if (leaf_cell < 0) {
        ok = false;  // a cycle: not a tree
        break;
      }
      const int other = leaf_node < n ? n + cj[leaf_cell] : ci[leaf_cell];
      f[leaf_cell] = rest[leaf_node];
      rest[other] -= rest[leaf_node];
      rest[leaf_node] = 0.0;
      used[leaf_cell] = true;
    }
    if (!ok) continue;
    double total = 0.0;
    for (int c = 0; c < k && ok; ++c) {
      if (f[c] < -1e-12) ok = false;
      total += f[c] * cost[ci[c]][cj[c]];
    }
    if (ok) best = std::min(best, total);
  }
  return best;
}

TEST(EmdTest, TinyCasesMatchBruteForceAndLemon) {
  SignatureGeneratorOptions o;
  o.bands = 3;
  o.classes = 1;
  SignatureGenerator gen(o);
  std::uniform_int_distribution<int> size(1, 3);
  EmdSolver solver;
  LemonEmd lemon;
  for (int t = 0; t < 400; ++t) {
    const PreparedSignature a = Prep(gen.Random(size(gen.rng())));
    const PreparedSignature b = Prep(gen.Random(size(gen.rng())));
    std::vector<double> wa(a.weights(), a.weights() + a.size());
    std::vector<double> wb(b.weights(), b.weights() + b.size());
    std::vector<std::vector<double>> cost(a.size());
    for (int i = 0; i < a.size(); ++i) {
      for (int j = 0; j < b.size(); ++j) {
        cost[i].push_back(GroundDistance(a, i, b, j));
      }
    }
    const double brute = BruteForceEmd(wa, wb, cost);
    ExpectRelNear(solver.Distance(a, b), brute, 1e-9);
    ExpectRelNear(lemon.DistanceScalar(a, b), brute, 1e-9);
  }
}

TEST(EmdTest, HandComputedTwoByTwo) {
  // Masses (0.5, 0.5) vs (0.5, 0.5) on a line (only G' differs, W1 = 1):
  // features at 0, 1 vs 0.25, 0.75. Optimal: 0->0.25, 1->0.75, cost 0.25.
  GroundDistanceOptions o;
  o.w1 = 1.0;
  o.w2 = o.w3 = o.w4 = 0.0;
  auto make = [](double g0, double g1) {
    Signature s;
    s.features.push_back({0.5, g0, {0.0}, {0.0}, {0.0}});
    s.features.push_back({0.5, g1, {0.0}, {0.0}, {0.0}});
    return s;
  };
  EXPECT_NEAR(Emd(Prep(make(0.0, 1.0), o), Prep(make(0.25, 0.75), o)), 0.25,
              1e-15);
  EXPECT_NEAR(Emd(Prep(make(1.0, 0.0), o), Prep(make(0.25, 0.75), o)), 0.25,
              1e-15);
}

TEST(EmdTest, RandomPairsMatchLemon) {
  SignatureGeneratorOptions o;
  o.seed = 11;
  o.classes = 30;
  SignatureGenerator gen(o);
  std::mt19937_64 rng(12);
  std::uniform_int_distribution<int> size(1, 60);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  EmdSolver solver;
  LemonEmd lemon;
  double worst = 0.0;
  for (int t = 0; t < 10000; ++t) {
    Signature sa;
    Signature sb;
    if (t % 2 == 0) {  // clustered, often the same class: small EMDs
      sa = gen.Next();
      sb = gen.Next();
    } else {
      sa = gen.Random(size(rng));
      sb = gen.Random(size(rng));
    }
    const PreparedSignature a = Prep(sa);
    const PreparedSignature b = Prep(sb);
    const double ours = solver.Distance(a, b);
    const double ref = lemon.Distance(a, b);
    ASSERT_GE(ref, 0.0);
    worst = std::max(worst, std::abs(ours - ref) / std::max(ref, 1e-12));
    ASSERT_NEAR(ours, ref, 1e-6 * std::max(ref, 1e-12))
        << "pair " << t << " sizes " << a.size() << " x " << b.size();
  }
  RecordProperty("worst_relative_error", std::to_string(worst));
}

// Compact storage: the EMD on float32 coordinates stays within
// the documented bound (ground_distance.h) of the EMD computed by LEMON on
// Eq. 7 in double straight from the raw features.
TEST(EmdTest, Float32StorageErrorWithinBound) {
  SignatureGeneratorOptions o;
  o.seed = 31;
  o.classes = 10;
  SignatureGenerator gen(o);
  const GroundDistanceOptions ground;
  EmdSolver solver;
  LemonEmd lemon;
  double worst_ratio = 0.0;
  for (int t = 0; t < 400; ++t) {
    const Signature sa = t % 2 ? gen.Next() : gen.Random(1 + t % 60);
    const Signature sb = gen.Next();
    const PreparedSignature a = Prep(sa);
    const PreparedSignature b = Prep(sb);
    std::vector<double> costs;
    for (const Feature& x : sa.features) {
      for (const Feature& y : sb.features)
        costs.push_back(DirectEq7(x, y, ground));
    }
    const double exact64 = lemon.DistanceWithCosts(a, b, costs);
    ASSERT_GE(exact64, 0.0);
    const double slack = Float32EmdSlack(sa, sb, ground);
    const double ours = solver.Distance(a, b);
    // LEMON's integer scaling adds about 1e-12 of the largest cost.
    ASSERT_NEAR(ours, exact64, slack + 1e-9 * std::max(exact64, 1e-3))
        << "pair " << t;
    worst_ratio = std::max(worst_ratio, std::abs(ours - exact64) / slack);
  }
  RecordProperty("worst_error_over_bound", std::to_string(worst_ratio));
}

TEST(EmdTest, LargestSignaturesMatchLemon) {
  SignatureGeneratorOptions o;
  o.seed = 21;
  SignatureGenerator gen(o);
  EmdSolver solver;
  LemonEmd lemon;
  for (int t = 0; t < 5; ++t) {
    const PreparedSignature a = Prep(gen.Random(kMaxFeatures));
    const PreparedSignature b = Prep(gen.Random(kMaxFeatures));
    ExpectRelNear(solver.Distance(a, b), lemon.Distance(a, b), 1e-6);
  }
}

TEST(EmdTest, OneFeatureAgainstSixtyIsTheWeightedMean) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  EmdSolver solver;
  LemonEmd lemon;
  for (int t = 0; t < 20; ++t) {
    const PreparedSignature a = Prep(gen.Random(1));
    const PreparedSignature b = Prep(gen.Random(60));
    // Only one plan is feasible: all of a's mass to each b_j by weight.
    double expected = 0.0;
    for (int j = 0; j < b.size(); ++j) {
      expected += b.weight(j) * GroundDistance(a, 0, b, j);
    }
    ExpectRelNear(solver.Distance(a, b), expected, 1e-12);
    ExpectRelNear(solver.Distance(b, a), expected, 1e-12);
    ExpectRelNear(lemon.Distance(a, b), expected, 1e-9);
  }
}

TEST(EmdTest, IdenticalSignaturesAreAtZero) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  EmdSolver solver;
  std::mt19937_64 rng(3);
  for (int n : {1, 2, 30, 60, 200}) {
    Signature s = gen.Random(n);
    const PreparedSignature a = Prep(s);
    EXPECT_EQ(solver.Distance(a, a), 0.0) << n;
    // Same features in another order: still 0.
    std::shuffle(s.features.begin(), s.features.end(), rng);
    const PreparedSignature b = Prep(s);
    EXPECT_NEAR(solver.Distance(a, b), 0.0, 1e-12) << n;
  }
}

TEST(EmdTest, ZeroGroundDistancesGiveZero) {
  // Every feature has the same coordinates; masses differ.
  Signature a;
  Signature b;
  for (int i = 0; i < 7; ++i) {
    a.features.push_back({1.0 / 7, 0.3, {1, 2}, {0.5, 0.5}, {0.1, 0.2}});
  }
  for (int j = 0; j < 4; ++j) {
    b.features.push_back(
        {j < 3 ? 0.1 : 0.7, 0.3, {1, 2}, {0.5, 0.5}, {0.1, 0.2}});
  }
  EXPECT_EQ(Emd(Prep(a), Prep(b)), 0.0);
}

TEST(EmdTest, ManyTiesAndZeroMassesMatchLemon) {
  // Coordinates on a coarse grid and equal or zero masses: many equal
  // costs, many degenerate pivots.
  std::mt19937_64 rng(5);
  std::uniform_int_distribution<int> level(0, 2);
  std::uniform_int_distribution<int> size(1, 40);
  EmdSolver solver;
  LemonEmd lemon;
  auto make = [&](int n, bool zero_masses) {
    Signature s;
    int positive = 0;
    for (int i = 0; i < n; ++i) {
      Feature f;
      f.weight = (zero_masses && i % 3 == 1) ? 0.0 : 1.0;
      positive += f.weight > 0 ? 1 : 0;
      f.integral_geodesic = 0.5 * level(rng);
      f.curvature = {1.0 * level(rng), 1.0 * level(rng)};
      f.area = {0.5 * level(rng), 0.5 * level(rng)};
      f.distance = {0.1 * level(rng), 0.1 * level(rng)};
      s.features.push_back(f);
    }
    for (Feature& f : s.features) f.weight /= positive;
    return s;
  };
  int64_t degenerate = 0;
  for (int t = 0; t < 2000; ++t) {
    const bool zero = t % 2 == 1;
    const PreparedSignature a = Prep(make(size(rng), zero));
    const PreparedSignature b = Prep(make(size(rng), !zero));
    const double ours = solver.Distance(a, b);
    degenerate += solver.Stats().degenerate_pivots;
    ExpectRelNear(ours, lemon.Distance(a, b), 1e-6);
  }
  EXPECT_GT(degenerate, 0);  // the case is really degenerate
}

TEST(EmdTest, FlowIsAFeasiblePlanWhoseCostIsTheEmd) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  EmdSolver solver;
  for (int t = 0; t < 50; ++t) {
    const PreparedSignature a = Prep(gen.Next());
    const PreparedSignature b = Prep(gen.Next());
    const double d = solver.Distance(a, b);
    std::vector<double> rows(a.size(), 0.0);
    std::vector<double> cols(b.size(), 0.0);
    double cost = 0.0;
    for (const EmdSolver::FlowEntry& e : solver.LastFlow()) {
      EXPECT_GT(e.mass, 0.0);
      rows[e.i] += e.mass;
      cols[e.j] += e.mass;
      cost += e.mass * GroundDistance(a, e.i, b, e.j);
    }
    for (int i = 0; i < a.size(); ++i) EXPECT_NEAR(rows[i], a.weight(i), 1e-12);
    for (int j = 0; j < b.size(); ++j) EXPECT_NEAR(cols[j], b.weight(j), 1e-12);
    EXPECT_NEAR(cost, d, 1e-12);
    EXPECT_GE(solver.Stats().pivots, solver.Stats().degenerate_pivots);
  }
}

// ForMixedPairs calls body(t, a, b) for `count` pairs of signatures
// (members of generated classes and unclustered ones of 1 to 60
// features, mixed), drawn from seeds `seed` and seed + 1.
void ForMixedPairs(uint64_t seed, int count,
                   const std::function<void(int, const PreparedSignature&,
                                            const PreparedSignature&)>& body) {
  SignatureGeneratorOptions o;
  o.seed = seed;
  SignatureGenerator gen(o);
  std::mt19937_64 rng(seed + 1);
  std::uniform_int_distribution<int> size(1, 60);
  for (int t = 0; t < count; ++t) {
    const PreparedSignature a =
        Prep(t % 2 ? gen.Next() : gen.Random(size(rng)));
    const PreparedSignature b =
        Prep(t % 3 ? gen.Next() : gen.Random(size(rng)));
    body(t, a, b);
  }
}

TEST(EmdTest, LowerBoundNeverExceedsEmd) {
  EmdSolver solver;
  double tightest = 0.0;
  ForMixedPairs(
      9, 5000,
      [&](int t, const PreparedSignature& a, const PreparedSignature& b) {
        const double lb = EmdLowerBound(a, b);
        const double d = solver.Distance(a, b);
        ASSERT_GE(lb, 0.0);
        ASSERT_LE(lb, d * (1 + 1e-12) + 1e-15) << t;
        if (d > 0) tightest = std::max(tightest, lb / d);
      });
  EXPECT_GT(tightest, 0.1);  // the bound is not trivially 0
}

// The relaxed transport bound against its definition (brute force over the
// ground distances) and against the exact EMD; and it is tighter than the
// centroid bound on average between unrelated signatures.
TEST(EmdTest, RelaxedBoundMatchesDefinitionAndNeverExceedsEmd) {
  EmdSolver solver;
  double relaxed_sum = 0.0;
  double centroid_sum = 0.0;
  ForMixedPairs(
      19, 3000,
      [&](int t, const PreparedSignature& a, const PreparedSignature& b) {
        // Definition, from GroundDistance (scalar code, not the matrix kernel).
        double rows = 0.0;
        for (int i = 0; i < a.size(); ++i) {
          double best = 1e300;
          for (int j = 0; j < b.size(); ++j) {
            best = std::min(best, GroundDistance(a, i, b, j));
          }
          rows += a.weight(i) * best;
        }
        double cols = 0.0;
        for (int j = 0; j < b.size(); ++j) {
          double best = 1e300;
          for (int i = 0; i < a.size(); ++i) {
            best = std::min(best, GroundDistance(a, i, b, j));
          }
          cols += b.weight(j) * best;
        }
        const double rb = solver.RelaxedBound(a, b);
        ExpectRelNear(rb, std::max(rows, cols), 1e-12);
        EXPECT_EQ(RelaxedTransportBound(a, b), rb);
        const double d = solver.Distance(a, b);
        ASSERT_LE(rb, d * (1 + 1e-12) + 1e-15) << t;
        relaxed_sum += rb;
        centroid_sum += EmdLowerBound(a, b);
      });
  EXPECT_GT(relaxed_sum, centroid_sum);
}

// The capacity-constrained bound against an independent form of its
// definition: each line's relaxed problem min { sum_j g_j c_j : sum_j g_j =
// w, 0 <= g_j <= cap_j } equals, by LP duality, the maximum over t of
// w t - sum_j cap_j max(0, t - c_j), a concave piecewise linear function
// whose maximum lies at a breakpoint t = c_j; computed here from the scalar
// GroundDistance. And it lies between the relaxed transport bound and the
// exact EMD, and is strictly tighter than the former on average.
double DualLine(double mass, const std::vector<double>& cost,
                const std::vector<double>& cap) {
  double best = 0.0;
  for (double t : cost) {
    double g = mass * t;
    for (size_t j = 0; j < cost.size(); ++j)
      g -= cap[j] * std::max(0.0, t - cost[j]);
    best = std::max(best, g);
  }
  return best;
}

TEST(EmdTest, ConstrainedBoundMatchesItsDualAndLiesBetweenRelaxedAndEmd) {
  EmdSolver solver;
  double constrained_sum = 0.0;
  double relaxed_sum = 0.0;
  ForMixedPairs(
      29, 3000,
      [&](int t, const PreparedSignature& a, const PreparedSignature& b) {
        std::vector<double> wa(a.weights(), a.weights() + a.size());
        std::vector<double> wb(b.weights(), b.weights() + b.size());
        double rows = 0.0;
        for (int i = 0; i < a.size(); ++i) {
          std::vector<double> c;
          for (int j = 0; j < b.size(); ++j)
            c.push_back(GroundDistance(a, i, b, j));
          rows += DualLine(wa[i], c, wb);
        }
        double cols = 0.0;
        for (int j = 0; j < b.size(); ++j) {
          std::vector<double> c;
          for (int i = 0; i < a.size(); ++i)
            c.push_back(GroundDistance(a, i, b, j));
          cols += DualLine(wb[j], c, wa);
        }
        const double cb = solver.ConstrainedBound(a, b);
        ExpectRelNear(cb, std::max(rows, cols), 1e-9);
        EXPECT_EQ(ConstrainedTransportBound(a, b), cb);
        const double rb = solver.RelaxedBound(a, b);
        ASSERT_GE(cb, rb * (1 - 1e-12)) << t;
        const double d = solver.Distance(a, b);
        ASSERT_LE(cb, d * (1 + 1e-12) + 1e-15) << t;
        // The float32 form: below the double one (hence the EMD) by its
        // rounding margin, at most 2 theta of it (emd.cc).
        const double cb32 = solver.ConstrainedBound32(a, b);
        EXPECT_EQ(ConstrainedTransportBound32(a, b), cb32);
        const double theta = internal::Float32MatrixError(a.bands());
        ASSERT_LE(cb32, cb * (1 + 1e-12) + 1e-15) << t;
        ASSERT_GE(cb32, cb * (1 - 2 * theta) - 1e-15) << t;
        ASSERT_LE(cb32, d * (1 + 1e-12) + 1e-15) << t;
        constrained_sum += cb;
        relaxed_sum += rb;
      });
  EXPECT_GT(constrained_sum, relaxed_sum * 1.01);
}

// Distance after RelaxedBound reuses the pair's matrix only for that pair:
// the EMD equals a fresh solver's, whatever came in between, including a
// signature re-prepared at the same address.
TEST(EmdTest, DistanceAfterRelaxedBoundEqualsFreshDistance) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  EmdSolver solver;
  PreparedSignature a = Prep(gen.Next());
  PreparedSignature b = Prep(gen.Next());
  const PreparedSignature c = Prep(gen.Next());
  for (int t = 0; t < 200; ++t) {
    EmdSolver fresh;
    solver.RelaxedBound(a, b);
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));  // kept after
    solver.RelaxedBound(a, c);
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));  // other pair
    solver.RelaxedBound(a, b);
    a = Prep(gen.Next());  // same object, new content and serial
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));
    solver.RelaxedBound(b, a);
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));  // transposed
    solver.ConstrainedBound(a, b);
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));
    solver.ConstrainedBound(b, a);
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));
    solver.ConstrainedBound(a, b);
    solver.ConstrainedBound32(a, c);  // another pair, float32 matrix
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));
    solver.ConstrainedBound32(a, b);
    EXPECT_EQ(solver.Distance(a, b), fresh.Distance(a, b));
    std::swap(a, b);
  }
}

TEST(EmdTest, LowerBoundIsExactForSingleFeatures) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  for (int t = 0; t < 100; ++t) {
    const PreparedSignature a = Prep(gen.Random(1));
    const PreparedSignature b = Prep(gen.Random(1));
    EXPECT_NEAR(EmdLowerBound(a, b), GroundDistance(a, 0, b, 0), 1e-12);
    EXPECT_NEAR(Emd(a, b), GroundDistance(a, 0, b, 0), 1e-15);
  }
}

TEST(EmdTest, WarmSolverDoesNotAllocate) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  std::vector<PreparedSignature> sigs;
  for (int n : {kMaxFeatures, 1, 30, 7, 60, 120}) {
    sigs.push_back(Prep(gen.Random(n)));
  }
  EmdSolver solver;
  solver.Distance(sigs[0], sigs[0]);  // warm-up at the largest size
  const int64_t before = ::tpr::testing::Allocations();
  double sum = 0.0;
  for (const PreparedSignature& a : sigs) {
    for (const PreparedSignature& b : sigs) sum += solver.Distance(a, b);
  }
  EXPECT_EQ(::tpr::testing::Allocations(), before);
  EXPECT_GT(sum, 0.0);
}

TEST(EmdTest, ConcurrentCallsAgreeWithSequential) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  std::vector<PreparedSignature> sigs;
  for (int t = 0; t < 40; ++t) sigs.push_back(Prep(gen.Next()));
  std::vector<double> expected;
  for (size_t i = 0; i + 1 < sigs.size(); ++i) {
    expected.push_back(Emd(sigs[i], sigs[i + 1]));
  }
  std::vector<std::thread> threads;
  std::atomic<int> mismatches{0};
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (int rep = 0; rep < 20; ++rep) {
        for (size_t i = 0; i + 1 < sigs.size(); ++i) {
          if (Emd(sigs[i], sigs[i + 1]) != expected[i]) ++mismatches;
        }
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(mismatches.load(), 0);
}

TEST(EmdTest, SignaturesArePrefetchedEarlyWhileMostItemsPassLevelOne) {
  // The search's prefetch policy: before any bound, and while at least half
  // of the level-1 items went on to level 2, the signature is prefetched
  // with the centroid row.
  EXPECT_TRUE(PrefetchSignatureEarly(0, 0));
  EXPECT_TRUE(PrefetchSignatureEarly(10, 5));
  EXPECT_TRUE(PrefetchSignatureEarly(10, 9));
  EXPECT_FALSE(PrefetchSignatureEarly(10, 4));
  EXPECT_FALSE(PrefetchSignatureEarly(1, 0));
}

}  // namespace
}  // namespace tpr::index
