// Critical Point Analysis (4.3, Table 1): hand-checked fronts on surfaces of
// revolution, the pocket of Fig. 3 B on a spiked grid, stars.
#include "extractor/lib/critical_points.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include "extractor/lib/geodesic.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/synth/synth.h"
#include "gtest/gtest.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

bool Contains(const std::vector<int32_t>& v, int32_t x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

TEST(VertexLinksTest, ClosedFansHaveAsManyLinkEdgesAsNeighbours) {
  const Mesh m = testing::Icosphere(2);
  const VertexLinks links = VertexLinks::Build(m);
  ASSERT_EQ(links.num_vertices(), static_cast<int32_t>(m.positions.size()));
  for (int32_t v = 0; v < links.num_vertices(); ++v) {
    EXPECT_EQ((links.link_end(v) - links.link_begin(v)) / 2, links.degree(v));
    EXPECT_TRUE(
        std::is_sorted(links.neighbors_begin(v), links.neighbors_end(v)));
  }
  Mesh tri;
  tri.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  tri.triangles = {{0, 1, 2}};
  const VertexLinks t = VertexLinks::Build(tri);
  EXPECT_EQ(t.degree(0), 2);
  ASSERT_EQ(t.link_end(0) - t.link_begin(0), 2);
  EXPECT_EQ(t.link_begin(0)[0], 1);
  EXPECT_EQ(t.link_begin(0)[1], 2);
}

// From one pole of a surface of revolution the front is a shrinking loop:
// the other pole is the only maximum, and nothing branches.
TEST(CriticalPointsTest, CapsuleAndDumbbellHaveOneMaximumAtTheOtherPole) {
  for (const Mesh& m : {testing::Capsule(1.0, 3.0, 60, 32),
                        testing::Dumbbell(1.0, 0.8, 0.35, 1.5, 90, 32)}) {
    const MeshGraph graph = MeshGraph::Build(m);
    const VertexLinks links = VertexLinks::Build(m);
    const int32_t top = 0;
    const int32_t bottom = static_cast<int32_t>(m.positions.size()) - 1;
    absl::StatusOr<CriticalPoints> cp =
        AnalyzeCriticalPoints(graph, links, top, {});
    ASSERT_TRUE(cp.ok()) << cp.status();
    EXPECT_EQ(cp->maxima, std::vector<int32_t>{bottom});
    EXPECT_TRUE(cp->saddles.empty());
    EXPECT_EQ(cp->distances[top], 0.0);
  }
}

// A flat 11 x 11 grid with one vertex p raised into a spike: the front
// flows around p and meets itself behind it, leaving p as a one-vertex
// pocket (Fig. 3 B). With n = 1 the pocket is an invalid cycle: no saddle,
// p disallowed, so no maximum at p. With n = 0 it is a valid cycle: LSD's
// answer, a saddle behind p and a maximum at p.
Mesh SpikedGrid(int32_t* spike) {
  // Diagonals alternate so that the grid is symmetric about y = 5.
  Mesh m = testing::Rectangle(10.0, 10.0, 10, 10);
  *spike = 5 * 11 + 4;
  m.positions[*spike].z() = 4.0;
  return m;
}

TEST(CriticalPointsTest, OneVertexPocketIsFilteredWithNEqualsOne) {
  int32_t spike = -1;
  const Mesh m = SpikedGrid(&spike);
  GeodesicOptions plain;
  plain.unfold_opposite_edges = false;
  const MeshGraph graph = MeshGraph::Build(m, plain);
  const VertexLinks links = VertexLinks::Build(m);
  const int32_t source = 5 * 11 + 0;  // Left middle, in line with the spike.
  auto near_spike = [&](const std::vector<int32_t>& vs) {
    for (int32_t v : vs) {
      if ((m.positions[v] - m.positions[spike]).head<2>().norm() < 1.5 &&
          v != spike)
        return true;
    }
    return false;
  };

  CriticalPointOptions filtered;  // n = 1
  absl::StatusOr<CriticalPoints> a =
      AnalyzeCriticalPoints(graph, links, source, filtered);
  ASSERT_TRUE(a.ok());
  EXPECT_FALSE(Contains(a->maxima, spike));
  EXPECT_FALSE(near_spike(a->saddles));
  EXPECT_GE(a->candidates_one_valid_cycle, 1);

  CriticalPointOptions lsd;
  lsd.cycle_min_vertices = 0;
  absl::StatusOr<CriticalPoints> b =
      AnalyzeCriticalPoints(graph, links, source, lsd);
  ASSERT_TRUE(b.ok());
  EXPECT_TRUE(Contains(b->maxima, spike));
  EXPECT_TRUE(near_spike(b->saddles));
}

// Table 1 row "0": when every cycle is invalid the candidate itself becomes
// a maximum. With n larger than any front near v, no saddle survives and
// every candidate is counted in row 0 or row 1.
TEST(CriticalPointsTest, HugeNTurnsEveryCandidateIntoRowsZeroOrOne) {
  synth::ShapeOptions o;
  o.target_vertices = 3000;
  absl::StatusOr<Mesh> m = synth::GenerateStar(5, o);
  ASSERT_TRUE(m.ok());
  const MeshGraph graph = MeshGraph::Build(*m);
  const VertexLinks links = VertexLinks::Build(*m);
  CriticalPointOptions huge;
  huge.cycle_min_vertices = 100000;
  huge.search_hops = 100001;
  absl::StatusOr<CriticalPoints> cp =
      AnalyzeCriticalPoints(graph, links, 0, huge);
  ASSERT_TRUE(cp.ok());
  EXPECT_TRUE(cp->saddles.empty());
  EXPECT_EQ(cp->candidates_one_valid_cycle, 0);
  EXPECT_EQ(cp->candidates_no_valid_cycle, cp->saddle_candidates);
  for (int k : {0, 1, 2}) {
    CriticalPointOptions opt;
    opt.cycle_min_vertices = k;
    absl::StatusOr<CriticalPoints> c =
        AnalyzeCriticalPoints(graph, links, 0, opt);
    ASSERT_TRUE(c.ok());
    // Every candidate falls in exactly one row of Table 1.
    EXPECT_EQ(static_cast<int>(c->saddles.size()) +
                  c->candidates_one_valid_cycle + c->candidates_no_valid_cycle,
              c->saddle_candidates);
    // The search is bounded: a few dozen vertices per candidate.
    EXPECT_LE(c->search_visits,
              int64_t{2000} * std::max(1, c->saddle_candidates));
  }
}

// From one arm tip of a k-arm star every other tip is a maximum and the
// front branches at the ball (at least k - 2 saddles).
TEST(CriticalPointsTest, StarFromATipFindsTheOtherTips) {
  for (int arms : {3, 6, 7}) {
    synth::ShapeOptions o;
    o.target_vertices = 5000;
    absl::StatusOr<Mesh> m = synth::GenerateStar(arms, o);
    absl::StatusOr<synth::Skeleton> sk = synth::StarSkeleton(arms, 0, o);
    ASSERT_TRUE(m.ok() && sk.ok());
    const MeshGraph graph = MeshGraph::Build(*m);
    const VertexLinks links = VertexLinks::Build(*m);
    std::vector<Eigen::Vector3d> tips;
    for (const synth::Bone& b : sk->bones) {
      if (b.name.find("outer") != std::string::npos) tips.push_back(b.end);
    }
    ASSERT_EQ(static_cast<int>(tips.size()), arms);
    // Source: the vertex nearest to tip 0.
    int32_t source = 0;
    for (int32_t v = 0; v < graph.num_vertices(); ++v) {
      if ((m->positions[v] - tips[0]).norm() <
          (m->positions[source] - tips[0]).norm())
        source = v;
    }
    absl::StatusOr<CriticalPoints> cp =
        AnalyzeCriticalPoints(graph, links, source, {});
    ASSERT_TRUE(cp.ok());
    for (int t = 1; t < arms; ++t) {
      double best = 1e300;
      for (int32_t v : cp->maxima)
        best = std::min(best, (m->positions[v] - tips[t]).norm());
      EXPECT_LT(best, 0.25) << arms << " arms, tip " << t;
    }
    EXPECT_GE(static_cast<int>(cp->saddles.size()), arms - 2);
  }
}

TEST(CriticalPointsTest, RejectsBadArguments) {
  const Mesh m = testing::Icosphere(1);
  const MeshGraph graph = MeshGraph::Build(m);
  const VertexLinks links = VertexLinks::Build(m);
  EXPECT_EQ(AnalyzeCriticalPoints(graph, links, -1, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(AnalyzeCriticalPoints(graph, links, graph.num_vertices(), {})
                .status()
                .code(),
            absl::StatusCode::kInvalidArgument);
  CriticalPointOptions bad;
  bad.search_hops = 1;
  EXPECT_EQ(AnalyzeCriticalPoints(graph, links, 0, bad).status().code(),
            absl::StatusCode::kInvalidArgument);
  const VertexLinks other = VertexLinks::Build(testing::Icosphere(2));
  EXPECT_EQ(AnalyzeCriticalPoints(graph, other, 0, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// ExtractSignature takes a topological point's field from the Critical
// Point Analysis of the source point at the same vertex instead of a new
// sweep. That is exact only if the analysis's own Dijkstra gives the
// solver's distances bit for bit (both are the least fixed point of the
// same rounded relaxations d(u) = min_v d(v) + l(v, u), whatever the order
// of ties): checked here from several sources on test meshes, generated
// shapes and, when ../shared is present, a few SHREC meshes.
TEST(CriticalPointsTest, DistancesEqualAFreshSweep) {
  std::vector<Mesh> meshes = {testing::Icosphere(3),
                              testing::Capsule(0.5, 3.0, 40, 24),
                              testing::Tube(1.0, 3.0, 20, 24)};
  synth::ShapeOptions shape;
  shape.target_vertices = 2000;
  for (const char* name : {"biped_adult", "octopus", "ant", "hand"}) {
    absl::StatusOr<Mesh> m = synth::GenerateShape(name, 2, shape);
    if (m.ok()) meshes.push_back(*std::move(m));
  }
  ASSERT_GE(meshes.size(), 6u);
  const char* env = std::getenv("TPR_SHARED_DIR");
  const std::string dir = std::string(env != nullptr ? env : TPR_SHARED_DIR) +
                          "/data/shrec07-watertight";
  std::ifstream manifest(dir + "/MANIFEST.txt");
  std::string path, label;
  for (int i = 0; i < 40 && manifest >> path >> label; ++i) {
    if (i % 10 != 0) continue;  // four meshes of different classes
    absl::StatusOr<LoadedMesh> m = LoadMeshFromFile(dir + "/" + path, {});
    ASSERT_TRUE(m.ok()) << path << ": " << m.status();
    meshes.push_back(std::move(m->mesh));
  }
  for (size_t i = 0; i < meshes.size(); ++i) {
    const MeshGraph graph = MeshGraph::Build(meshes[i]);
    DijkstraSolver solver(graph);
    const int32_t n = graph.num_vertices();
    for (int32_t source : {0, n / 3, n - 1}) {
      absl::StatusOr<CriticalPoints> cp =
          AnalyzeCriticalPoints(graph, graph.links(), source, {});
      ASSERT_TRUE(cp.ok()) << cp.status();
      EXPECT_EQ(cp->distances, solver.Run(source))
          << "mesh " << i << " source " << source;
    }
  }
}

}  // namespace
}  // namespace tpr::extract
