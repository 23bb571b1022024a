// VpTree against the brute-force oracle under cheap vector metrics (L1, L2),
// over uniform, clustered and tie-heavy data: k-NN, ranked and range search,
// filters, buffers, serialization and corrupt bytes.
#include "indexer/lib/vp_tree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "indexer/lib/brute_force_index.h"

namespace tpr::index {
namespace {

using Point = std::vector<double>;

double L2(const Point& a, const Point& b) {
  double s = 0.0;
  for (size_t i = 0; i < a.size(); ++i) s += (a[i] - b[i]) * (a[i] - b[i]);
  return std::sqrt(s);
}

double L1(const Point& a, const Point& b) {
  double s = 0.0;
  for (size_t i = 0; i < a.size(); ++i) s += std::fabs(a[i] - b[i]);
  return s;
}

// L-infinity <= L2 and <= L1: a valid cheap lower bound for both.
double LInf(const Point& a, const Point& b) {
  double s = 0.0;
  for (size_t i = 0; i < a.size(); ++i) s = std::max(s, std::fabs(a[i] - b[i]));
  return s;
}

std::vector<Point> Uniform(size_t n, size_t dim, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Point> points(n, Point(dim));
  for (Point& p : points) {
    for (double& x : p) x = u(rng);
  }
  return points;
}

std::vector<Point> Clustered(size_t n, size_t dim, size_t clusters,
                             double spread, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, spread);
  std::vector<Point> centers = Uniform(clusters, dim, seed + 1);
  std::vector<Point> points(n, Point(dim));
  for (Point& p : points) {
    const Point& c = centers[rng() % clusters];
    for (size_t i = 0; i < dim; ++i) p[i] = c[i] + g(rng);
  }
  return points;
}

// Integer lattice points, each repeated: many exactly equal distances.
std::vector<Point> TieHeavy(size_t n, size_t dim, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Point> points;
  while (points.size() < n) {
    Point p(dim);
    for (double& x : p) x = static_cast<double>(rng() % 4);
    const size_t copies = 1 + rng() % 3;
    for (size_t c = 0; c < copies && points.size() < n; ++c)
      points.push_back(p);
  }
  return points;
}

using Metric = double (*)(const Point&, const Point&);

// Small buckets, so that a few thousand points make a deep tree.
VpTreeOptions DeepTree() {
  VpTreeOptions options;
  options.leaf_size = 16;
  return options;
}

VpTree BuildTree(const std::vector<Point>& points, Metric metric,
                 VpTreeOptions options = DeepTree()) {
  absl::StatusOr<VpTree> tree = VpTree::Build(
      points.size(),
      [&points, metric](uint32_t i, uint32_t j) {
        return metric(points[i], points[j]);
      },
      options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return std::move(tree).value();
}

QuerySpec Spec(const std::vector<Point>& points, const Point& query,
               Metric metric) {
  QuerySpec spec;
  spec.distance = [&points, &query, metric](uint32_t i, double* d) {
    d[0] = metric(query, points[i]);
  };
  return spec;
}

void ExpectSame(const std::vector<ItemNeighbor>& got,
                const std::vector<ItemNeighbor>& want, const std::string& ctx) {
  ASSERT_EQ(got.size(), want.size()) << ctx;
  for (size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].item, want[i].item) << ctx << " rank " << i;
    EXPECT_EQ(got[i].distance, want[i].distance) << ctx << " rank " << i;
  }
}

// Queries: half data points (exact hits, duplicates), half fresh points.
std::vector<Point> Queries(const std::vector<Point>& points, size_t count,
                           uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<Point> queries;
  const size_t dim = points.empty() ? 4 : points[0].size();
  std::vector<Point> fresh = Uniform(count, dim, seed + 7);
  for (size_t q = 0; q < count; ++q) {
    if (q % 2 == 0 && !points.empty()) {
      queries.push_back(points[rng() % points.size()]);
    } else {
      queries.push_back(fresh[q]);
    }
  }
  return queries;
}

void CheckKnnAgainstBruteForce(const std::vector<Point>& points, Metric metric,
                               size_t num_queries, VpTreeOptions options,
                               uint64_t seed) {
  const VpTree tree = BuildTree(points, metric, options);
  const BruteForceIndex oracle(points.size());
  const std::vector<Point> queries = Queries(points, num_queries, seed);
  const size_t ks[] = {1, 3, 10, 50};
  for (size_t q = 0; q < queries.size(); ++q) {
    const size_t k = ks[q % 4];
    SearchStats stats;
    int64_t calls = 0;
    QuerySpec spec = Spec(points, queries[q], metric);
    QuerySpec counted = spec;
    counted.distance = [&](uint32_t i, double* d) {
      ++calls;
      spec.distance(i, d);
    };
    const std::vector<ItemNeighbor> got = tree.Knn(counted, k, &stats);
    const std::vector<ItemNeighbor> want = oracle.Knn(spec, k);
    ExpectSame(got, want,
               "query " + std::to_string(q) + " k " + std::to_string(k));
    EXPECT_EQ(stats.emd_computations, calls);
    EXPECT_LE(stats.emd_computations, static_cast<int64_t>(points.size()));
  }
}

TEST(VpTreeTest, MatchesBruteForceOnUniformData) {
  CheckKnnAgainstBruteForce(Uniform(2000, 6, 11), L2, 1000, DeepTree(), 12);
  CheckKnnAgainstBruteForce(Uniform(2000, 6, 13), L2, 200, VpTreeOptions{}, 14);
}

TEST(VpTreeTest, MatchesBruteForceOnClusteredData) {
  CheckKnnAgainstBruteForce(Clustered(3000, 10, 20, 0.02, 21), L1, 1000,
                            DeepTree(), 22);
}

TEST(VpTreeTest, MatchesBruteForceWithTiesAndDuplicates) {
  CheckKnnAgainstBruteForce(TieHeavy(1500, 3, 31), L1, 1000, DeepTree(), 32);
}

TEST(VpTreeTest, MatchesBruteForceForOtherShapes) {
  const std::vector<Point> points = Clustered(700, 5, 7, 0.05, 41);
  for (size_t leaf : {1, 2, 5, 64, 1000}) {
    VpTreeOptions options;
    options.leaf_size = leaf;
    options.vantage_candidates = leaf % 2 == 0 ? 1 : 4;
    options.vantage_sample = 4;
    options.seed = leaf;
    CheckKnnAgainstBruteForce(points, L2, 100, options, 42 + leaf);
  }
}

TEST(VpTreeTest, SmallAndEmptyTrees) {
  for (size_t n : {0, 1, 2, 3, 17}) {
    const std::vector<Point> points = TieHeavy(n, 2, 50 + n);
    const VpTree tree = BuildTree(points, L2);
    EXPECT_EQ(tree.size(), n);
    const BruteForceIndex oracle(n);
    const Point query = {1.5, 0.5};
    for (size_t k : {0, 1, 2, 5, 100}) {
      const std::vector<ItemNeighbor> got =
          tree.Knn(Spec(points, query, L2), k);
      EXPECT_EQ(got.size(), std::min(k, n));
      ExpectSame(got, oracle.Knn(Spec(points, query, L2), k),
                 "n " + std::to_string(n) + " k " + std::to_string(k));
    }
  }
}

TEST(VpTreeTest, RankedSearchYieldsTheWholeBruteForceOrder) {
  const std::vector<Point> points = Clustered(1500, 4, 8, 0.03, 61);
  const VpTree tree = BuildTree(points, L2);
  const BruteForceIndex oracle(points.size());
  for (const Point& query : Queries(points, 20, 62)) {
    std::unique_ptr<NeighborCursor> cursor =
        tree.Search(Spec(points, query, L2));
    std::vector<ItemNeighbor> got;
    while (std::optional<ItemNeighbor> next = cursor->Next())
      got.push_back(*next);
    EXPECT_FALSE(cursor->Next().has_value());
    ExpectSame(got, oracle.Range(Spec(points, query, L2)), "ranked");
    EXPECT_EQ(cursor->stats().emd_computations,
              static_cast<int64_t>(points.size()));
  }
}

TEST(VpTreeTest, RangeSearchMatchesBruteForce) {
  const std::vector<Point> points = Clustered(2000, 6, 15, 0.04, 71);
  const VpTree tree = BuildTree(points, L1);
  const BruteForceIndex oracle(points.size());
  std::mt19937_64 rng(72);
  std::uniform_real_distribution<double> radius(0.0, 0.6);
  for (const Point& query : Queries(points, 300, 73)) {
    QuerySpec spec = Spec(points, query, L1);
    spec.radius = radius(rng);
    ExpectSame(tree.Range(spec), oracle.Range(spec), "range");
  }
  // A radius of exactly a stored distance keeps that item (<=).
  QuerySpec spec = Spec(points, points[5], L1);
  spec.radius = L1(points[5], points[9]);
  const std::vector<ItemNeighbor> got = tree.Range(spec);
  EXPECT_TRUE(std::any_of(got.begin(), got.end(),
                          [](const ItemNeighbor& n) { return n.item == 9; }));
}

// A cascade of two bounds (|‖q‖ - ‖x‖| <= L2, then LInf <= L2): exact
// results, each level consulted, and no more metric evaluations than with
// the first bound alone.
TEST(VpTreeTest, BoundCascadeKeepsResultsAndRefinesInOrder) {
  const std::vector<Point> points = Clustered(3000, 8, 30, 0.02, 83);
  const VpTree tree = BuildTree(points, L2);
  const BruteForceIndex oracle(points.size());
  auto norm = [](const Point& p) {
    double s = 0.0;
    for (double x : p) s += x * x;
    return std::sqrt(s);
  };
  int64_t one_level = 0;
  int64_t two_levels = 0;
  for (const Point& query : Queries(points, 200, 84)) {
    QuerySpec spec = Spec(points, query, L2);
    const double qn = norm(query);
    spec.lower_bounds.push_back([&points, &norm, qn](uint32_t i) {
      return std::abs(qn - norm(points[i]));
    });
    SearchStats first;
    const std::vector<ItemNeighbor> got1 = tree.Knn(spec, 10, &first);
    int64_t second_calls = 0;
    spec.lower_bounds.push_back([&points, &query, &second_calls](uint32_t i) {
      ++second_calls;
      return LInf(query, points[i]);
    });
    SearchStats both;
    ExpectSame(tree.Knn(spec, 10, &both), oracle.Knn(spec, 10), "cascade");
    ExpectSame(got1, oracle.Knn(spec, 10), "first bound");
    EXPECT_GT(second_calls, 0);
    // The second level runs only on items that passed the first.
    EXPECT_LE(second_calls, first.emd_computations);
    one_level += first.emd_computations;
    two_levels += both.emd_computations;
  }
  EXPECT_LE(two_levels, one_level);
}

// The prefetch hint changes nothing and tells the truth: answers and work
// are those of the same search without it (and brute force), and each
// hint names an item together with the number of bounds it has had so
// far (the level it needs next); most hinted items are then refined.
TEST(VpTreeTest, PrefetchHintNamesTheNextItemAndItsLevel) {
  const std::vector<Point> points = Clustered(3000, 8, 30, 0.02, 85);
  const VpTree tree = BuildTree(points, L2);
  const BruteForceIndex oracle(points.size());
  int64_t hints = 0;
  int64_t hinted_then_refined = 0;
  for (const Point& query : Queries(points, 100, 86)) {
    std::vector<int> applied(points.size(), 0);
    std::vector<int> hinted(points.size(), -1);
    QuerySpec spec = Spec(points, query, L2);
    for (int level = 0; level < 2; ++level) {
      spec.lower_bounds.push_back([&points, &query, &applied, &hinted,
                                   &hinted_then_refined, level](uint32_t i) {
        EXPECT_EQ(applied[i], level) << "item " << i;
        if (hinted[i] == level) ++hinted_then_refined;
        ++applied[i];
        return level == 0 ? 0.5 * LInf(query, points[i])
                          : LInf(query, points[i]);
      });
    }
    const QuerySpec plain = spec;
    SearchStats without;
    const std::vector<ItemNeighbor> want = tree.Knn(plain, 10, &without);
    std::fill(applied.begin(), applied.end(), 0);
    spec.prefetch_vantage_points = false;  // their hints: the test below
    spec.prefetch = [&applied, &hinted, &hints](uint32_t i, size_t level) {
      ++hints;
      EXPECT_EQ(static_cast<size_t>(applied[i]), level) << "item " << i;
      hinted[i] = static_cast<int>(level);
    };
    SearchStats with;
    ExpectSame(tree.Knn(spec, 10, &with), want, "prefetch");
    ExpectSame(want, oracle.Knn(plain, 10), "brute force");
    EXPECT_EQ(with.emd_computations, without.emd_computations);
    EXPECT_EQ(with.lower_bounds, without.lower_bounds);
  }
  EXPECT_GT(hints, 0);
  EXPECT_GT(hinted_then_refined, hints / 2);
}

// With prefetch_vantage_points, every vantage point whose distance the
// search computes was hinted (at level lower_bounds.size(): only the
// distance left) when its node was queued, except the root's, which is
// queued before the search starts; answers and work are unchanged.
TEST(VpTreeTest, PrefetchHintsEachVantagePointBeforeItsDistance) {
  const std::vector<Point> points = Clustered(3000, 8, 30, 0.02, 87);
  const VpTree tree = BuildTree(points, L2);
  const BruteForceIndex oracle(points.size());
  int64_t vantage_distances = 0;
  for (const Point& query : Queries(points, 50, 88)) {
    std::vector<int> bounded(points.size(), 0);
    std::vector<int> hinted(points.size(), 0);
    QuerySpec spec = Spec(points, query, L2);
    spec.lower_bounds.push_back([&points, &query, &bounded](uint32_t i) {
      ++bounded[i];
      return LInf(query, points[i]);
    });
    const QuerySpec plain = spec;
    SearchStats without;
    const std::vector<ItemNeighbor> want = tree.Knn(plain, 10, &without);
    std::fill(bounded.begin(), bounded.end(), 0);
    int64_t unhinted = 0;  // vantage points computed without a hint
    int64_t computed = 0;
    const auto distance = spec.distance;
    spec.distance = [&](uint32_t i, double* d) {
      if (bounded[i] == 0) {  // never bounded: a vantage point
        ++computed;
        if (hinted[i] == 0) ++unhinted;
      }
      distance(i, d);
    };
    spec.prefetch_vantage_points = true;
    spec.prefetch = [&hinted](uint32_t i, size_t level) {
      if (level == 1) ++hinted[i];  // lower_bounds.size()
    };
    SearchStats with;
    ExpectSame(tree.Knn(spec, 10, &with), want, "prefetch");
    ExpectSame(want, oracle.Knn(plain, 10), "brute force");
    EXPECT_EQ(with.emd_computations, without.emd_computations);
    EXPECT_EQ(with.lower_bounds, without.lower_bounds);
    EXPECT_EQ(unhinted, 1) << "only the root's vantage point";
    vantage_distances += computed;
  }
  EXPECT_GT(vantage_distances, 50 * 2);
}

TEST(VpTreeTest, LowerBoundFilterKeepsResultsAndSavesDistances) {
  const std::vector<Point> points = Clustered(3000, 8, 30, 0.02, 81);
  const VpTree tree = BuildTree(points, L2);
  const BruteForceIndex oracle(points.size());
  int64_t with_bound = 0;
  int64_t without_bound = 0;
  int64_t bounds = 0;
  for (const Point& query : Queries(points, 300, 82)) {
    QuerySpec spec = Spec(points, query, L2);
    SearchStats plain;
    const std::vector<ItemNeighbor> want = tree.Knn(spec, 10, &plain);
    spec.lower_bounds.push_back(
        [&points, &query](uint32_t i) { return LInf(query, points[i]); });
    SearchStats filtered;
    ExpectSame(tree.Knn(spec, 10, &filtered), oracle.Knn(spec, 10), "bound");
    ExpectSame(want, oracle.Knn(spec, 10), "plain");
    with_bound += filtered.emd_computations;
    without_bound += plain.emd_computations;
    bounds += filtered.lower_bounds;
  }
  EXPECT_GT(bounds, 0);
  EXPECT_LE(with_bound, without_bound);
}

TEST(VpTreeTest, PrunesOnClusteredData) {
  // Not a speed test: a count of metric evaluations, which must be far
  // below n for a tree to be worth having on well-separated clusters.
  const std::vector<Point> points = Clustered(5000, 6, 50, 0.01, 91);
  const VpTree tree = BuildTree(points, L2);
  int64_t total = 0;
  const std::vector<Point> queries = Queries(points, 200, 92);
  for (const Point& query : queries) {
    SearchStats stats;
    tree.Knn(Spec(points, query, L2), 10, &stats);
    total += stats.emd_computations;
    EXPECT_GT(stats.nodes_visited, 0);
  }
  EXPECT_LT(total / static_cast<int64_t>(queries.size()), 5000 / 5);
}

TEST(VpTreeTest, AcceptFilterExtraItemsAndTieOrder) {
  // Items 0..n-1 in the tree, n..n+m-1 as an unindexed buffer; odd items
  // rejected; ties broken in reverse item order.
  const std::vector<Point> all = TieHeavy(1300, 2, 101);
  const size_t n = 1000;
  const std::vector<Point> tree_points(all.begin(), all.begin() + n);
  const VpTree tree = BuildTree(tree_points, L1);
  const BruteForceIndex oracle(n);
  for (const Point& query : Queries(all, 200, 102)) {
    QuerySpec spec = Spec(all, query, L1);
    int accept_calls = 0;
    std::vector<int> seen(all.size(), 0);
    spec.accept = [&](uint32_t i) {
      ++accept_calls;
      ++seen[i];
      return i % 2 == 0;
    };
    spec.tie_less = [](uint32_t a, uint32_t b) { return a > b; };
    for (size_t i = n; i < all.size(); ++i) spec.extra_items.push_back(i);
    const std::vector<ItemNeighbor> got = tree.Knn(spec, 25);
    for (int s : seen) EXPECT_LE(s, 1);
    spec.accept = [](uint32_t i) { return i % 2 == 0; };
    ExpectSame(got, oracle.Knn(spec, 25), "filtered");
    for (const ItemNeighbor& nb : got) EXPECT_EQ(nb.item % 2, 0u);
  }
}

TEST(VpTreeTest, UnavailablePointsAreSkippedNotFatal) {
  // NaN distances (signatures missing after a reload) for rejected items,
  // vantage points included: results still exact over the rest.
  const std::vector<Point> points = Clustered(1200, 4, 10, 0.05, 111);
  const VpTree tree = BuildTree(points, L2);
  const BruteForceIndex oracle(points.size());
  for (const Point& query : Queries(points, 200, 112)) {
    QuerySpec spec = Spec(points, query, L2);
    spec.distance = [&points, &query](uint32_t i, double* d) {
      d[0] = i % 3 == 0 ? std::numeric_limits<double>::quiet_NaN()
                        : L2(query, points[i]);
    };
    spec.accept = [](uint32_t i) { return i % 3 != 0; };
    ExpectSame(tree.Knn(spec, 10), oracle.Knn(spec, 10), "nan");
  }
}

TEST(VpTreeTest, SerializationRoundTripKeepsResults) {
  const std::vector<Point> points = Clustered(2500, 5, 12, 0.03, 121);
  const VpTree tree = BuildTree(points, L2);
  const std::string bytes = tree.Serialize();
  absl::StatusOr<VpTree> loaded = VpTree::Deserialize(bytes);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->size(), tree.size());
  EXPECT_EQ(loaded->node_count(), tree.node_count());
  EXPECT_EQ(loaded->height(), tree.height());
  EXPECT_EQ(loaded->Serialize(), bytes);
  const BruteForceIndex oracle(points.size());
  for (const Point& query : Queries(points, 500, 122)) {
    SearchStats a, b;
    const std::vector<ItemNeighbor> got =
        loaded->Knn(Spec(points, query, L2), 7, &a);
    ExpectSame(got, oracle.Knn(Spec(points, query, L2), 7), "reloaded");
    tree.Knn(Spec(points, query, L2), 7, &b);
    EXPECT_EQ(a.emd_computations, b.emd_computations);
  }
  absl::StatusOr<VpTree> empty = VpTree::Deserialize(VpTree().Serialize());
  ASSERT_TRUE(empty.ok()) << empty.status();
  EXPECT_EQ(empty->size(), 0u);
}

TEST(VpTreeTest, BuildIsDeterministicAcrossThreads) {
  const std::vector<Point> points = Clustered(3000, 5, 12, 0.03, 131);
  VpTreeOptions options = DeepTree();
  const std::string one = BuildTree(points, L2, options).Serialize();
  options.build_threads = 2;
  EXPECT_EQ(BuildTree(points, L2, options).Serialize(), one);
  options.seed = 99;
  EXPECT_NE(BuildTree(points, L2, options).Serialize(), one);
}

TEST(VpTreeTest, BadOptionsAndCancellation) {
  const std::vector<Point> points = Uniform(100, 3, 141);
  PairDistance d = [&points](uint32_t i, uint32_t j) {
    return L2(points[i], points[j]);
  };
  VpTreeOptions options = DeepTree();
  options.leaf_size = 0;
  EXPECT_EQ(VpTree::Build(points.size(), d, options).status().code(),
            absl::StatusCode::kInvalidArgument);
  std::atomic<bool> cancel{true};
  EXPECT_EQ(VpTree::Build(points.size(), d, {}, &cancel).status().code(),
            absl::StatusCode::kCancelled);
}

// Three terms over the coordinates of one point: L2 of dims 0-1, L1 of dims
// 2-3, L-infinity of dims 4-5 (each a metric on the whole point, a
// pseudometric: points equal in those dims are at 0).
void ThreeTerms(const Point& a, const Point& b, double* out) {
  const Point a0(a.begin(), a.begin() + 2), b0(b.begin(), b.begin() + 2);
  const Point a1(a.begin() + 2, a.begin() + 4),
      b1(b.begin() + 2, b.begin() + 4);
  const Point a2(a.begin() + 4, a.end()), b2(b.begin() + 4, b.end());
  out[0] = L2(a0, b0);
  out[1] = L1(a1, b1);
  out[2] = LInf(a2, b2);
}

VpTree BuildThreeTermTree(const std::vector<Point>& points,
                          const TermVector& build_weights,
                          VpTreeOptions options = DeepTree()) {
  absl::StatusOr<VpTree> tree = VpTree::Build(
      points.size(), 3,
      [&points](uint32_t i, uint32_t j, double* out) {
        ThreeTerms(points[i], points[j], out);
      },
      build_weights, options);
  EXPECT_TRUE(tree.ok()) << tree.status();
  return std::move(tree).value();
}

// The query's terms; a term of weight 0 is left unwritten (NaN), as the
// contract allows, so a search that read it would go wrong.
QuerySpec ThreeTermSpec(const std::vector<Point>& points, const Point& query,
                        const TermVector& w) {
  QuerySpec spec;
  spec.weights = w;
  spec.distance = [&points, &query, w](uint32_t i, double* d) {
    double all[3];
    ThreeTerms(query, points[i], all);
    for (int t = 0; t < 3; ++t) {
      d[t] = w[t] > 0.0 ? all[t] : std::numeric_limits<double>::quiet_NaN();
    }
  };
  return spec;
}

// The oracle's distance, written out here: sum_t w_t d_t in term order.
double WeightedOracle(const Point& a, const Point& b, const TermVector& w) {
  double all[3];
  ThreeTerms(a, b, all);
  double d = 0.0;
  for (int t = 0; t < 3; ++t) {
    if (w[t] > 0.0) d += w[t] * all[t];
  }
  return d;
}

// Weightings: the build's, each term alone, pairs with a 0, random ones.
std::vector<TermVector> Weightings(uint64_t seed) {
  std::vector<TermVector> out = {{1, 1, 0},   {1, 0, 0},    {0, 1, 0},
                                 {0, 0, 1},   {0.25, 1, 0}, {1, 0.1, 0},
                                 {0, 2, 0.5}, {3, 0, 1},    {1, 1, 1}};
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 4.0);
  for (int r = 0; r < 6; ++r) {
    TermVector w = {u(rng), u(rng), u(rng)};
    w[rng() % 3] = 0.0;  // some term unused
    out.push_back(w);
  }
  return out;
}

// One tree built under {1, 1, 0} answers every non-negative weighting
// exactly: k-NN, the whole ranked order and range search equal brute force
// (order and distances, ties included), and the oracle's distances are the
// weighted sums written out independently.
TEST(VpTreeTermsTest, EveryWeightingMatchesBruteForce) {
  std::vector<Point> points = Clustered(1500, 6, 12, 0.05, 161);
  // Duplicated points: exact ties under every weighting.
  for (size_t i = 0; i < 100; ++i) points.push_back(points[i * 7]);
  const VpTree tree = BuildThreeTermTree(points, {1, 1, 0});
  EXPECT_EQ(tree.terms(), 3u);
  EXPECT_EQ(tree.build_weights(), (TermVector{1, 1, 0}));
  const BruteForceIndex oracle(points.size());
  std::mt19937_64 rng(162);
  std::uniform_real_distribution<double> radius(0.05, 0.5);
  for (const TermVector& w : Weightings(163)) {
    const std::string ctx = "w " + std::to_string(w[0]) + " " +
                            std::to_string(w[1]) + " " + std::to_string(w[2]);
    for (const Point& query : Queries(points, 30, 164)) {
      const QuerySpec spec = ThreeTermSpec(points, query, w);
      const std::vector<ItemNeighbor> want = oracle.Knn(spec, 10);
      ASSERT_EQ(want.size(), 10u);
      for (const ItemNeighbor& nb : want) {
        EXPECT_EQ(nb.distance, WeightedOracle(query, points[nb.item], w));
      }
      SearchStats stats;
      ExpectSame(tree.Knn(spec, 10, &stats), want, ctx + " knn");
      EXPECT_LT(stats.emd_computations, static_cast<int64_t>(points.size()));
      QuerySpec ranged = spec;
      ranged.radius = radius(rng);
      ExpectSame(tree.Range(ranged), oracle.Range(ranged), ctx + " range");
    }
    const Point& query = points[3];
    std::unique_ptr<NeighborCursor> cursor =
        tree.Search(ThreeTermSpec(points, query, w));
    std::vector<ItemNeighbor> got;
    while (std::optional<ItemNeighbor> next = cursor->Next()) {
      got.push_back(*next);
    }
    ExpectSame(got, oracle.Range(ThreeTermSpec(points, query, w)),
               ctx + " ranked");
  }
}

// The tree splits on its build weighting but stores every term: a tree built
// on the first term alone still answers the others exactly, with filters,
// an unindexed buffer, tie order and after a serialization round trip.
TEST(VpTreeTermsTest, OtherBuildWeightsFiltersBufferAndReload) {
  const std::vector<Point> all = TieHeavy(1300, 6, 171);
  const size_t n = 1000;
  const std::vector<Point> tree_points(all.begin(), all.begin() + n);
  const VpTree built = BuildThreeTermTree(tree_points, {1, 0, 0});
  absl::StatusOr<VpTree> loaded = VpTree::Deserialize(built.Serialize());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ(loaded->Serialize(), built.Serialize());
  EXPECT_EQ(loaded->build_weights(), (TermVector{1, 0, 0}));
  const BruteForceIndex oracle(n);
  for (const VpTree* tree : std::vector<const VpTree*>{&built, &*loaded}) {
    for (const TermVector& w : Weightings(172)) {
      for (const Point& query : Queries(all, 20, 173)) {
        QuerySpec spec = ThreeTermSpec(all, query, w);
        spec.accept = [](uint32_t i) { return i % 5 != 1; };
        spec.tie_less = [](uint32_t a, uint32_t b) { return a > b; };
        for (size_t i = n; i < all.size(); ++i) spec.extra_items.push_back(i);
        ExpectSame(tree->Knn(spec, 25), oracle.Knn(spec, 25), "filtered");
        ExpectSame(tree->Knn(spec, 2000), oracle.Knn(spec, 2000), "k > n");
      }
    }
  }
}

// Per-term bounds are never looser than the weighted distance's own: under
// the build weighting the tree computes no more distances than a one-term
// tree built on that weighted distance (same seed, same splits).
TEST(VpTreeTermsTest, PerTermBoundsPruneAtLeastAsWellAsTheSum) {
  const std::vector<Point> points = Clustered(4000, 6, 40, 0.02, 181);
  const TermVector w = {1, 1, 0};
  const VpTree terms = BuildThreeTermTree(points, w);
  const VpTree sum = BuildTree(points, [](const Point& a, const Point& b) {
    return WeightedOracle(a, b, {1, 1, 0});
  });
  int64_t by_terms = 0, by_sum = 0;
  for (const Point& query : Queries(points, 100, 182)) {
    SearchStats a, b;
    const std::vector<ItemNeighbor> got =
        terms.Knn(ThreeTermSpec(points, query, w), 10, &a);
    QuerySpec one;
    one.distance = [&](uint32_t i, double* d) {
      d[0] = WeightedOracle(query, points[i], {1, 1, 0});
    };
    ExpectSame(got, sum.Knn(one, 10, &b), "same answers");
    by_terms += a.emd_computations;
    by_sum += b.emd_computations;
  }
  // The float32 storage's larger slack (1e-7 against 1e-9) may reorder a
  // near-tie of bounds; beyond that the count cannot grow.
  EXPECT_LE(by_terms, by_sum + by_sum / 100);
  EXPECT_LT(by_terms, 100 * 4000 / 5);
}

TEST(VpTreeTermsTest, BadTermsAndBuildWeights) {
  const std::vector<Point> points = Uniform(50, 6, 191);
  PairTerms d = [&points](uint32_t i, uint32_t j, double* out) {
    ThreeTerms(points[i], points[j], out);
  };
  for (const TermVector& w : {TermVector{0, 0, 0}, TermVector{-1, 1, 0},
                              TermVector{1, std::nan(""), 0}}) {
    EXPECT_EQ(VpTree::Build(points.size(), 3, d, w, {}).status().code(),
              absl::StatusCode::kInvalidArgument);
  }
  // A weight past the tree's terms is not part of it.
  EXPECT_TRUE(VpTree::Build(points.size(), 2, d, {1, 0, -1}, {}).ok());
  EXPECT_EQ(VpTree::Build(points.size(), 0, d, {1, 0, 0}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(VpTree::Build(points.size(), 4, d, {1, 0, 0}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(ValidateWeights({0, 0, 5}, 2).ok());
  EXPECT_TRUE(ValidateWeights({0, 0.5, 5}, 2).ok());
}

// FNV-1a 64, written here independently of vp_tree.cc, to forge bytes whose
// checksum is right but whose structure is not.
uint64_t Fnv(const std::string& s, size_t n) {
  uint64_t h = 0xcbf29ce484222325ull;
  for (size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(s[i]);
    h *= 0x100000001b3ull;
  }
  return h;
}

void Reseal(std::string* bytes) {
  const uint64_t h = Fnv(*bytes, bytes->size() - 8);
  for (int i = 0; i < 8; ++i)
    (*bytes)[bytes->size() - 8 + i] = static_cast<char>(h >> (8 * i));
}

TEST(VpTreeTest, CorruptBytesAreErrorsNotCrashes) {
  const std::vector<Point> points = Clustered(60, 3, 4, 0.05, 151);
  VpTreeOptions options;
  options.leaf_size = 3;
  const std::string bytes = BuildTree(points, L2, options).Serialize();
  auto is_error = [](const absl::Status& s) {
    return s.code() == absl::StatusCode::kDataLoss ||
           s.code() == absl::StatusCode::kInvalidArgument;
  };
  // Every truncation.
  for (size_t len = 0; len < bytes.size(); ++len) {
    EXPECT_TRUE(is_error(VpTree::Deserialize(bytes.substr(0, len)).status()))
        << len;
  }
  // Every single-byte change, with the checksum left alone (DATA_LOSS or a
  // bad header) and recomputed (structure checks must catch or accept it;
  // accepted trees must still be searchable without crashing).
  std::mt19937_64 rng(152);
  int accepted = 0;
  for (size_t pos = 0; pos < bytes.size(); ++pos) {
    std::string bad = bytes;
    bad[pos] = static_cast<char>(bad[pos] ^ (1 + rng() % 255));
    EXPECT_TRUE(is_error(VpTree::Deserialize(bad).status())) << pos;
    if (pos >= 8 && pos + 8 < bytes.size()) {
      Reseal(&bad);
      absl::StatusOr<VpTree> t = VpTree::Deserialize(bad);
      if (t.ok()) {
        ++accepted;
        // Only stored distances can be wrong: the search must not crash.
        t->Knn(Spec(points, points[0], L2), 5);
      } else {
        EXPECT_TRUE(is_error(t.status())) << t.status();
      }
    }
  }
  EXPECT_LT(accepted, static_cast<int>(bytes.size()));
  EXPECT_EQ(VpTree::Deserialize("not a tree at all").status().code(),
            absl::StatusCode::kInvalidArgument);
  std::string version = bytes;
  version[6] = 9;
  EXPECT_EQ(VpTree::Deserialize(version).status().code(),
            absl::StatusCode::kInvalidArgument);
  std::string checksum = bytes;
  checksum.back() = static_cast<char>(checksum.back() ^ 1);
  EXPECT_EQ(VpTree::Deserialize(checksum).status().code(),
            absl::StatusCode::kDataLoss);
}

}  // namespace
}  // namespace tpr::index
