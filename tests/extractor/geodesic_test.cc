// Tests of the mesh graph and Dijkstra geodesics (4.1, 4.2, 5.1) against
// analytic distances (sphere, tube) and brute-force oracles.
#include "extractor/lib/geodesic.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <map>
#include <new>
#include <queue>
#include <random>
#include <utility>
#include <vector>

#include "gtest/gtest.h"
#include "tests/allocation_counter.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct ErrorStats {
  double mean = 0.0;
  double max = 0.0;
};

// Relative error of graph distance against an exact geodesic from several
// sources; vertices closer than `min_distance` are left out (relative error
// of a one-edge path is meaningless).
template <typename Exact>
ErrorStats MeasureError(const Mesh& mesh, const GeodesicOptions& options,
                        Exact exact, double min_distance) {
  const MeshGraph graph = MeshGraph::Build(mesh, options);
  DijkstraSolver solver(graph);
  ErrorStats s;
  int64_t count = 0;
  const int32_t n = graph.num_vertices();
  for (int32_t src : {0, n / 3, (2 * n) / 3}) {
    const std::vector<double>& d = solver.Run(src);
    for (int32_t v = 0; v < n; ++v) {
      const double e = exact(mesh.positions[src], mesh.positions[v]);
      if (e < min_distance) continue;
      // Graph paths are paths on the inscribed polyhedron, never shorter
      // than its geodesics, which are at most about 1% shorter than the
      // smooth surface's at these resolutions.
      EXPECT_GE(d[v], e * (1.0 - 0.01)) << "vertex " << v;
      const double rel = (d[v] - e) / e;
      s.mean += rel;
      s.max = std::max(s.max, rel);
      ++count;
    }
  }
  s.mean /= std::max<int64_t>(1, count);
  return s;
}

double GreatCircle(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0));
}

TEST(GeodesicTest, UnitSphereDistancesApproximateGreatCircles) {
  // Plain edge Dijkstra zig-zags: its error does not vanish with refinement.
  // Unfolding each pair of triangles removes most of the zig-zag.
  for (int level = 2; level <= 5; ++level) {
    const Mesh mesh = testing::Icosphere(level);
    const ErrorStats plain = MeasureError(mesh, {false}, GreatCircle, 0.3);
    const ErrorStats unfolded = MeasureError(mesh, {true}, GreatCircle, 0.3);
    std::printf(
        "sphere level %d (%zu vertices): plain mean %.4f max %.4f, "
        "unfolded mean %.4f max %.4f\n",
        level, mesh.positions.size(), plain.mean, plain.max, unfolded.mean,
        unfolded.max);
    // Measured (levels 2-5): plain mean 6-8%, max 21-22%; unfolded mean
    // 0.6-1.5%, max 3-5%.
    EXPECT_LT(plain.max, 0.25) << "level " << level;
    EXPECT_LT(plain.mean, 0.10) << "level " << level;
    EXPECT_LT(unfolded.max, 0.06) << "level " << level;
    EXPECT_LT(unfolded.mean, 0.02) << "level " << level;
    EXPECT_LT(unfolded.mean, 0.3 * plain.mean) << "level " << level;
  }
}

TEST(GeodesicTest, LargestDistanceOnUnitSphereIsAboutPi) {
  for (bool unfold : {false, true}) {
    const Mesh mesh = testing::Icosphere(4);
    const MeshGraph graph = MeshGraph::Build(mesh, {unfold});
    DijkstraSolver solver(graph);
    const std::vector<double>& d = solver.Run(0);
    const double far = *std::max_element(d.begin(), d.end());
    EXPECT_GT(far, kPi * (1.0 - 0.005));  // inscribed polyhedron
    EXPECT_LT(far, kPi * (unfold ? 1.03 : 1.10)) << "unfold " << unfold;
  }
}

TEST(GeodesicTest, TubeDistancesApproximateUnrolledDistance) {
  const double radius = 1.0;
  const double length = 6.0;
  const Mesh mesh = testing::Tube(radius, length, 60, 64);
  auto unrolled = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    double dtheta =
        std::abs(std::atan2(a.y(), a.x()) - std::atan2(b.y(), b.x()));
    dtheta = std::min(dtheta, 2.0 * kPi - dtheta);
    return std::hypot(radius * dtheta, a.z() - b.z());
  };
  const ErrorStats plain = MeasureError(mesh, {false}, unrolled, 0.5);
  const ErrorStats unfolded = MeasureError(mesh, {true}, unrolled, 0.5);
  std::printf(
      "tube (%zu vertices): plain mean %.4f max %.4f, unfolded mean "
      "%.4f max %.4f\n",
      mesh.positions.size(), plain.mean, plain.max, unfolded.mean,
      unfolded.max);
  // Measured: plain mean 10%, max 18%; unfolded mean 2.3%, max 4.6%.
  EXPECT_LT(plain.max, 0.20);
  EXPECT_LT(plain.mean, 0.12);
  EXPECT_LT(unfolded.max, 0.06);
  EXPECT_LT(unfolded.mean, 0.03);
  EXPECT_LT(unfolded.mean, 0.3 * plain.mean);
}

TEST(GeodesicTest, VertexAreasSumToSurfaceArea) {
  const Mesh mesh = testing::Icosphere(4);
  const MeshGraph graph = MeshGraph::Build(mesh);
  double sum = 0.0;
  for (double a : graph.vertex_areas()) {
    EXPECT_GT(a, 0.0);
    sum += a;
  }
  EXPECT_NEAR(sum, graph.total_area(), 1e-9);
  // The inscribed polyhedron's area approaches 4 pi from below.
  EXPECT_LT(graph.total_area(), 4.0 * kPi);
  EXPECT_GT(graph.total_area(), 4.0 * kPi * 0.99);
  EXPECT_EQ(graph.num_components(), 1);
  // Icosphere: every vertex has 5 or 6 mesh edges; the plain graph is the
  // edge graph, the default one adds about as many unfolded arcs.
  const MeshGraph plain = MeshGraph::Build(mesh, {false});
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    EXPECT_GE(plain.neighbors(v).size(), 5u);
    EXPECT_LE(plain.neighbors(v).size(), 6u);
    EXPECT_EQ(graph.one_ring(v).size(), plain.neighbors(v).size());
    EXPECT_GT(graph.neighbors(v).size(), plain.neighbors(v).size());
  }
}

// Whether u and w are both in a triangle with v.
bool ShareTriangle(const Mesh& m, int32_t v, int32_t u, int32_t w) {
  for (const auto& t : m.triangles) {
    const bool hv = t[0] == v || t[1] == v || t[2] == v;
    const bool hu = t[0] == u || t[1] == u || t[2] == u;
    const bool hw = t[0] == w || t[1] == w || t[2] == w;
    if (hv && hu && hw) return true;
  }
  return false;
}

TEST(GeodesicTest, OneRingIsTheOrderedFanOnClosedMeshes) {
  const Mesh mesh = testing::Icosphere(2);
  const MeshGraph graph = MeshGraph::Build(mesh);
  const MeshGraph plain = MeshGraph::Build(mesh, {false});
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    const auto ring = graph.one_ring(v);
    std::vector<int32_t> sorted(ring.begin(), ring.end());
    std::sort(sorted.begin(), sorted.end());
    const auto nb = plain.neighbors(v);
    EXPECT_EQ(sorted, std::vector<int32_t>(nb.begin(), nb.end()));
    const Eigen::Vector3d& p = mesh.positions[v];
    for (size_t i = 0; i < ring.size(); ++i) {
      const int32_t a = ring[i];
      const int32_t b = ring[(i + 1) % ring.size()];  // closed fan
      EXPECT_TRUE(ShareTriangle(mesh, v, a, b)) << v;
      // Counter-clockwise seen from outside (the icosphere is oriented so).
      const Eigen::Vector3d n =
          (mesh.positions[a] - p).cross(mesh.positions[b] - p);
      EXPECT_GT(n.dot(p), 0.0) << v;
    }
  }
}

TEST(GeodesicTest, OneRingIsOpenAtTheBoundary) {
  const Mesh mesh = testing::Tube(1.0, 2.0, 4, 12);
  const MeshGraph graph = MeshGraph::Build(mesh);
  // Vertex 0 lies on the first ring, a boundary loop: 4 neighbours, an open
  // fan of 3 triangles.
  const auto ring = graph.one_ring(0);
  ASSERT_EQ(ring.size(), 4u);
  for (size_t i = 0; i + 1 < ring.size(); ++i) {
    EXPECT_TRUE(ShareTriangle(mesh, 0, ring[i], ring[i + 1]));
  }
  EXPECT_FALSE(ShareTriangle(mesh, 0, ring.back(), ring.front()));
}

class SolverFamilyTest : public ::testing::TestWithParam<int> {
 protected:
  // A family of meshes: closed, elongated, with boundary; plain and
  // unfolded graphs.
  static Mesh MakeMesh(int which) {
    switch (which % 3) {
      case 0:
        return testing::Icosphere(3);
      case 1:
        return testing::Capsule(0.5, 3.0, 40, 24);
      default:
        return testing::Tube(1.0, 3.0, 20, 24);
    }
  }
  static GeodesicOptions MakeOptions(int which) { return {which >= 3}; }
};

TEST_P(SolverFamilyTest, DistanceIsSymmetric) {
  const Mesh mesh = MakeMesh(GetParam());
  const MeshGraph graph = MeshGraph::Build(mesh, MakeOptions(GetParam()));
  DijkstraSolver solver(graph);
  std::mt19937 rng(7);
  std::uniform_int_distribution<int32_t> pick(0, graph.num_vertices() - 1);
  for (int i = 0; i < 20; ++i) {
    const int32_t a = pick(rng);
    const int32_t b = pick(rng);
    const double ab = solver.Run(a)[b];
    const double ba = solver.Run(b)[a];
    EXPECT_NEAR(ab, ba, 1e-12 * std::max(1.0, ab));
  }
}

TEST_P(SolverFamilyTest, MultiSourceIsMinOverSingleSourcesWithStartTimes) {
  const Mesh mesh = MakeMesh(GetParam());
  const MeshGraph graph = MeshGraph::Build(mesh, MakeOptions(GetParam()));
  DijkstraSolver solver(graph);
  const int32_t n = graph.num_vertices();
  const std::vector<int32_t> sources = {3, n / 2, n - 5, n / 4};
  const std::vector<double> starts = {0.4, 0.0, 1.3, 0.2};
  std::vector<std::vector<double>> single;
  for (int32_t s : sources) single.push_back(solver.Run(s));

  const std::vector<double> multi = solver.Run(sources, starts);
  const std::vector<int32_t> nearest = solver.nearest_source();
  for (int32_t v = 0; v < n; ++v) {
    double best = kUnreachable;
    for (size_t i = 0; i < sources.size(); ++i) {
      best = std::min(best, starts[i] + single[i][v]);
    }
    EXPECT_NEAR(multi[v], best, 1e-12) << "vertex " << v;
    // The labelled wavefront really achieves the distance.
    ASSERT_GE(nearest[v], 0);
    EXPECT_NEAR(starts[nearest[v]] + single[nearest[v]][v], multi[v], 1e-12);
  }

  // Vertex set (5.1): all starts zero, the same as empty initial values.
  const std::vector<double> set = solver.Run(sources);
  for (int32_t v = 0; v < n; ++v) {
    double best = kUnreachable;
    for (size_t i = 0; i < sources.size(); ++i)
      best = std::min(best, single[i][v]);
    EXPECT_NEAR(set[v], best, 1e-12);
  }
  for (int32_t s : sources) EXPECT_EQ(set[s], 0.0);
}

TEST_P(SolverFamilyTest, UniformStartTimeShiftsDistances) {
  const Mesh mesh = MakeMesh(GetParam());
  const MeshGraph graph = MeshGraph::Build(mesh, MakeOptions(GetParam()));
  DijkstraSolver solver(graph);
  const std::vector<double> base = solver.Run(11);
  const std::vector<int32_t> src = {11};
  const std::vector<double> start = {2.5};
  const std::vector<double>& shifted = solver.Run(src, start);
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    EXPECT_NEAR(shifted[v], base[v] + 2.5, 1e-12);
  }
}

TEST_P(SolverFamilyTest, OrderParentAndReuseAreConsistent) {
  const Mesh mesh = MakeMesh(GetParam());
  const MeshGraph graph = MeshGraph::Build(mesh, MakeOptions(GetParam()));
  DijkstraSolver solver(graph);
  const std::vector<double> first = solver.Run(5);
  const std::vector<int32_t> first_order = solver.order();
  // Settle order is by distance and covers every vertex once.
  ASSERT_EQ(first_order.size(), static_cast<size_t>(graph.num_vertices()));
  for (size_t i = 1; i < first_order.size(); ++i) {
    EXPECT_LE(first[first_order[i - 1]], first[first_order[i]]);
  }
  // Parents follow shortest-path edges.
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    const int32_t p = solver.parent()[v];
    if (v == 5) {
      EXPECT_EQ(p, -1);
      continue;
    }
    ASSERT_GE(p, 0);
    const auto nb = graph.neighbors(p);
    const auto it = std::find(nb.begin(), nb.end(), v);
    ASSERT_NE(it, nb.end());
    EXPECT_NEAR(first[v], first[p] + graph.lengths(p)[it - nb.begin()], 1e-12);
  }
  // Other sweeps in between (bounded, multi-source) leave no trace.
  RunOptions bounded;
  bounded.max_distance = 0.7;
  solver.Run(17, bounded);
  const std::vector<int32_t> two = {1, 2};
  solver.Run(two);
  EXPECT_EQ(solver.Run(5), first);
  EXPECT_EQ(solver.order(), first_order);
}

TEST_P(SolverFamilyTest, RepeatedSweepsDoNotAllocate) {
  const Mesh mesh = MakeMesh(GetParam());
  const MeshGraph graph = MeshGraph::Build(mesh, MakeOptions(GetParam()));
  const int64_t at_start = ::tpr::testing::Allocations();
  DijkstraSolver solver(graph);
  EXPECT_GT(::tpr::testing::Allocations(), at_start);  // the counter does count
  const int32_t n = graph.num_vertices();
  const std::vector<int32_t> set = {1, n / 2, n - 2};
  const std::vector<double> starts = {0.0, 0.3, 0.1};
  RunOptions bounded;
  bounded.max_distance = 0.5;
  auto sweeps = [&] {
    for (int32_t s = 0; s < n; s += std::max(1, n / 10)) solver.Run(s);
    solver.Run(set, starts);
    solver.Run(set);
    solver.Run(4, bounded);
  };
  sweeps();  // warm-up: buffers reach their sizes
  const int64_t before = ::tpr::testing::Allocations();
  sweeps();
  sweeps();
  EXPECT_EQ(::tpr::testing::Allocations() - before, 0);
}

TEST_P(SolverFamilyTest, BoundedRunMatchesFullRunInsideTheRadius) {
  const Mesh mesh = MakeMesh(GetParam());
  const MeshGraph graph = MeshGraph::Build(mesh, MakeOptions(GetParam()));
  DijkstraSolver solver(graph);
  const std::vector<double> full = solver.Run(9);
  RunOptions bounded;
  bounded.max_distance = 0.8;
  const std::vector<double>& part = solver.Run(9, bounded);
  size_t inside = 0;
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if (full[v] <= 0.8) {
      EXPECT_EQ(part[v], full[v]);
      ++inside;
    } else {
      EXPECT_EQ(part[v], kUnreachable);
      EXPECT_EQ(solver.nearest_source()[v], -1);
    }
  }
  EXPECT_EQ(solver.order().size(), inside);
  EXPECT_GT(inside, 1u);
  EXPECT_LT(inside, static_cast<size_t>(graph.num_vertices()));
}

// TextbookDistances is the independent oracle: Dijkstra with
// std::priority_queue and settled flags, from sources with start times.
std::vector<double> TextbookDistances(const MeshGraph& graph,
                                      const std::vector<int32_t>& sources,
                                      const std::vector<double>& starts,
                                      double max_distance = kUnreachable) {
  std::vector<double> d(graph.num_vertices(), kUnreachable);
  std::vector<char> done(graph.num_vertices(), 0);
  using Item = std::pair<double, int32_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (size_t i = 0; i < sources.size(); ++i) {
    const double t = starts.empty() ? 0.0 : starts[i];
    if (t < d[sources[i]]) {
      d[sources[i]] = t;
      queue.push({t, sources[i]});
    }
  }
  while (!queue.empty()) {
    const auto [key, v] = queue.top();
    queue.pop();
    if (done[v]) continue;
    done[v] = 1;
    for (size_t k = 0; k < graph.neighbors(v).size(); ++k) {
      const int32_t u = graph.neighbors(v)[k];
      const double nd = key + graph.lengths(v)[k];
      if (!done[u] && nd < d[u]) {
        d[u] = nd;
        queue.push({nd, u});
      }
    }
  }
  for (double& x : d) {
    if (x > max_distance) x = kUnreachable;
  }
  return d;
}

// The solver reuses its buffers and heap across runs (an unbounded run
// resets from its settle order, a bounded one from its touched list, the
// heap keeps a mask of its non-empty buckets): a mixed sequence of runs
// gives, run by run, the textbook Dijkstra's distances bit for bit and a
// fresh solver's distances, order, parents and labels.
TEST_P(SolverFamilyTest, MixedRunsMatchTextbookDijkstraAndAFreshSolver) {
  const Mesh mesh = MakeMesh(GetParam());
  const MeshGraph graph = MeshGraph::Build(mesh, MakeOptions(GetParam()));
  const int32_t n = graph.num_vertices();
  DijkstraSolver reused(graph);
  std::mt19937 rng(11);
  std::uniform_int_distribution<int32_t> pick(0, n - 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int run = 0; run < 24; ++run) {
    std::vector<int32_t> sources = {pick(rng)};
    std::vector<double> starts;
    if (run % 3 == 1) {
      sources.push_back(pick(rng));
      sources.push_back(pick(rng));
      starts = {unit(rng), 0.0, unit(rng)};
    }
    RunOptions options;
    if (run % 2 == 1) options.max_distance = 0.2 + 2.0 * unit(rng);
    const std::vector<double> got = reused.Run(sources, starts, options);
    EXPECT_EQ(got,
              TextbookDistances(graph, sources, starts, options.max_distance))
        << "run " << run;
    DijkstraSolver fresh(graph);
    EXPECT_EQ(fresh.Run(sources, starts, options), got) << "run " << run;
    EXPECT_EQ(fresh.order(), reused.order()) << "run " << run;
    EXPECT_EQ(fresh.parent(), reused.parent()) << "run " << run;
    EXPECT_EQ(fresh.nearest_source(), reused.nearest_source()) << "run " << run;
  }
}

INSTANTIATE_TEST_SUITE_P(Meshes, SolverFamilyTest, ::testing::Range(0, 6));

// The graph's rows against a brute-force construction from the triangles:
// every mesh edge with its length; with unfolding, for every edge with
// exactly two triangles (a, b, c) and (a, b, d), the arc (c, d) of length
// sqrt(|ac|^2 + |ad|^2 - 2 |ac| |ad| cos(A)), A the sum of the two angles
// at a, present when the unfolded segment crosses the open edge (both angle
// sums, at a and at b, below pi). Arcs within 1e-7 of that limit may go
// either way. Meshes: closed, with boundary, two components, a perturbed
// sphere (no collinear unfoldings), a degenerate triangle and an edge of
// three triangles.
TEST(GeodesicTest, RowsMatchBruteForceEdgesAndUnfoldedArcs) {
  Mesh perturbed = testing::Icosphere(2);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.03, 0.03);
  for (Eigen::Vector3d& q : perturbed.positions) {
    q += Eigen::Vector3d(jitter(rng), jitter(rng), jitter(rng));
  }
  Mesh odd;  // a degenerate triangle and an edge (0, 1) of three triangles
  odd.positions = {
      {0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.5, -1, 0.2}, {0.4, 0.2, 1}};
  odd.triangles = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}, {2, 2, 4}, {1, 2, 4}};
  const std::vector<Mesh> meshes = {
      testing::Icosphere(1),
      testing::Tube(1.0, 2.0, 4, 12),
      testing::Rectangle(2.0, 1.0, 5, 3),
      testing::Union(testing::Icosphere(1), testing::Tube(0.5, 1.0, 3, 8)),
      perturbed,
      odd};
  auto angle = [](const Eigen::Vector3d& u, const Eigen::Vector3d& v) {
    return std::acos(std::clamp(u.normalized().dot(v.normalized()), -1.0, 1.0));
  };
  int unfolded = 0;
  for (size_t m = 0; m < meshes.size(); ++m) {
    const Mesh& mesh = meshes[m];
    const auto& p = mesh.positions;
    std::map<std::pair<int32_t, int32_t>, std::vector<int32_t>> sides;
    for (const auto& t : mesh.triangles) {
      for (int k = 0; k < 3; ++k) {
        const int32_t a = t[k], b = t[(k + 1) % 3];
        if (a != b) {
          sides[{std::min(a, b), std::max(a, b)}].push_back(t[(k + 2) % 3]);
        }
      }
    }
    for (bool unfold : {false, true}) {
      // Per vertex: neighbour -> the lengths it must have (the shortest of
      // the definite candidates) and the optional ones.
      const int32_t n = static_cast<int32_t>(p.size());
      std::vector<std::map<int32_t, double>> must(n);
      std::vector<std::multimap<int32_t, double>> may(n);
      auto add = [&](int32_t u, int32_t v, double len, bool definite) {
        for (auto [x, y] : {std::pair{u, v}, std::pair{v, u}}) {
          if (!definite) {
            may[x].insert({y, len});
          } else if (!must[x].count(y) || len < must[x][y]) {
            must[x][y] = len;
          }
        }
      };
      for (const auto& [edge, opposite] : sides) {
        const auto [a, b] = edge;
        add(a, b, (p[a] - p[b]).norm(), true);
        if (!unfold || opposite.size() != 2 || opposite[0] == opposite[1]) {
          continue;
        }
        const int32_t c = opposite[0], d = opposite[1];
        const double at_a =
            angle(p[c] - p[a], p[b] - p[a]) + angle(p[d] - p[a], p[b] - p[a]);
        const double at_b =
            angle(p[c] - p[b], p[a] - p[b]) + angle(p[d] - p[b], p[a] - p[b]);
        const double ac = (p[c] - p[a]).norm(), ad = (p[d] - p[a]).norm();
        const double len = std::sqrt(
            std::max(0.0, ac * ac + ad * ad - 2.0 * ac * ad * std::cos(at_a)));
        const double margin = std::min(kPi - at_a, kPi - at_b);
        if (margin > 1e-7) {
          add(c, d, len, true);
          ++unfolded;
        } else if (margin > -1e-7) {
          add(c, d, len, false);
        }
      }
      const MeshGraph graph = MeshGraph::Build(mesh, {unfold});
      ASSERT_EQ(graph.num_vertices(), n);
      for (int32_t v = 0; v < n; ++v) {
        std::map<int32_t, double> row;
        for (size_t i = 0; i < graph.neighbors(v).size(); ++i) {
          EXPECT_TRUE(
              row.insert({graph.neighbors(v)[i], graph.lengths(v)[i]}).second)
              << "mesh " << m << " vertex " << v << ": repeated neighbour";
        }
        for (const auto& [u, len] : row) {
          const auto it = must[v].find(u);
          bool matched = it != must[v].end() &&
                         std::abs(len - it->second) <= 1e-12 * it->second;
          const auto [lo, hi] = may[v].equal_range(u);
          for (auto j = lo; j != hi && !matched; ++j) {
            matched = std::abs(len - j->second) <= 1e-12 * j->second &&
                      (it == must[v].end() || j->second <= it->second);
          }
          EXPECT_TRUE(matched) << "mesh " << m << " unfold " << unfold
                               << " arc " << v << "-" << u << " length " << len;
        }
        for (const auto& [u, len] : must[v]) {
          EXPECT_TRUE(row.count(u)) << "mesh " << m << " unfold " << unfold
                                    << " missing " << v << "-" << u;
        }
      }
    }
  }
  EXPECT_GT(unfolded, 100);  // the unfolding case is exercised
}

TEST(GeodesicTest, DistancesFollowRigidMotionAndScale) {
  const Mesh mesh = testing::Capsule(0.5, 2.0, 40, 24);
  const double scale = 2.3;
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(1.1, Eigen::Vector3d(3, -1, 2).normalized())
          .toRotationMatrix();
  Mesh moved = mesh;
  for (auto& p : moved.positions) {
    p = scale * (rotation * p) + Eigen::Vector3d(-4.0, 1.0, 0.5);
  }
  for (bool unfold : {false, true}) {
    const MeshGraph a = MeshGraph::Build(mesh, {unfold});
    const MeshGraph b = MeshGraph::Build(moved, {unfold});
    EXPECT_EQ(a.num_arcs(), b.num_arcs());
    EXPECT_NEAR(b.total_area(), scale * scale * a.total_area(),
                1e-9 * b.total_area());
    DijkstraSolver sa(a);
    DijkstraSolver sb(b);
    const std::vector<double> da = sa.Run(3);
    const std::vector<double>& db = sb.Run(3);
    for (int32_t v = 0; v < a.num_vertices(); ++v) {
      EXPECT_NEAR(db[v], scale * da[v], 1e-9 * std::max(1.0, db[v]));
    }
  }
}

TEST(GeodesicTest, TwoComponentsLeaveTheOtherUnreached) {
  const Mesh small = testing::Icosphere(1, 0.5);
  const Mesh big = testing::Icosphere(2, 2.0);
  const Mesh both = testing::Union(small, big);
  const MeshGraph graph = MeshGraph::Build(both);
  ASSERT_EQ(graph.num_components(), 2);
  EXPECT_EQ(graph.largest_component(),
            graph.component()[small.positions.size()]);
  DijkstraSolver solver(graph);
  const std::vector<double>& d = solver.Run(0);
  const int32_t split = static_cast<int32_t>(small.positions.size());
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if (v < split) {
      EXPECT_TRUE(std::isfinite(d[v]));
      EXPECT_EQ(solver.nearest_source()[v], 0);
    } else {
      EXPECT_EQ(d[v], kUnreachable);
      EXPECT_EQ(solver.nearest_source()[v], -1);
      EXPECT_EQ(solver.parent()[v], -1);
    }
  }
  EXPECT_EQ(solver.order().size(), static_cast<size_t>(split));
  // A source in each component reaches everything.
  const std::vector<int32_t> sources = {0, split};
  const std::vector<double>& e = solver.Run(sources);
  for (double x : e) EXPECT_TRUE(std::isfinite(x));
}

TEST(GeodesicTest, EmptySourceSetReachesNothing) {
  const Mesh mesh = testing::Icosphere(1);
  const MeshGraph graph = MeshGraph::Build(mesh);
  DijkstraSolver solver(graph);
  solver.Run(0);
  const std::vector<double>& d = solver.Run(absl::Span<const int32_t>());
  for (double x : d) EXPECT_EQ(x, kUnreachable);
  EXPECT_TRUE(solver.order().empty());
}

TEST(GeodesicTest, CreateRejectsBadMeshes) {
  Mesh m = testing::Icosphere(0);
  m.triangles[3][1] = 99;
  absl::StatusOr<MeshGraph> g = MeshGraph::Create(m);
  ASSERT_FALSE(g.ok());
  EXPECT_EQ(g.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(g.status().message().find("triangle 3"), absl::string_view::npos);

  Mesh nan = testing::Icosphere(0);
  nan.positions[4].x() = std::nan("");
  EXPECT_EQ(MeshGraph::Create(nan).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(MeshGraph::Create(Mesh{}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(MeshGraph::Create(testing::Icosphere(0)).ok());
}

TEST(GeodesicTest, UnreferencedVertexIsIsolated) {
  Mesh m = testing::Icosphere(1);
  m.positions.emplace_back(5.0, 5.0, 5.0);
  const MeshGraph graph = MeshGraph::Build(m);
  EXPECT_EQ(graph.num_components(), 2);
  const int32_t lone = graph.num_vertices() - 1;
  EXPECT_EQ(graph.vertex_areas()[lone], 0.0);
  EXPECT_TRUE(graph.neighbors(lone).empty());
  DijkstraSolver solver(graph);
  const std::vector<double>& d = solver.Run(lone);
  EXPECT_EQ(d[lone], 0.0);
  EXPECT_EQ(d[0], kUnreachable);
}

}  // namespace
}  // namespace tpr::extract
