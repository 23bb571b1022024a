// Topological Point Selection (4.4): the vote, the radius, the
// representative, on hand-made critical sets and on real ones.
#include "extractor/lib/topological_points.h"

#include <algorithm>
#include <map>
#include <queue>
#include <utility>
#include <vector>

#include "extractor/lib/critical_points.h"
#include "extractor/lib/geodesic.h"
#include "extractor/lib/source_points.h"
#include "extractor/synth/synth.h"
#include "gtest/gtest.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

// Capsule along z: vertex 0 is the top pole, the last the bottom pole.
class CapsuleSets : public ::testing::Test {
 protected:
  CapsuleSets()
      : mesh_(testing::Capsule(1.0, 4.0, 80, 24)),
        graph_(MeshGraph::Build(mesh_)),
        solver_(graph_) {}
  int32_t Nearest(const Eigen::Vector3d& x) const {
    int32_t best = 0;
    for (int32_t v = 0; v < graph_.num_vertices(); ++v) {
      if ((mesh_.positions[v] - x).norm() < (mesh_.positions[best] - x).norm())
        best = v;
    }
    return best;
  }
  Mesh mesh_;
  MeshGraph graph_;
  DijkstraSolver solver_;
};

TEST_F(CapsuleSets, MajorityOfSourcesValidatesARegion) {
  const int32_t top = 0;
  const int32_t top_near = Nearest({0.2, 0.0, 2.95});
  const int32_t bottom = graph_.num_vertices() - 1;
  const int32_t middle = Nearest({1.0, 0.0, 0.0});
  std::vector<CriticalPoints> sets(3);
  // Saddle at the middle of the cylinder: radius from the top is about
  // 3 (cap quarter circle pi/2 + 2 of cylinder = 3.57).
  sets[0].saddles = {middle};
  sets[0].maxima = {top};
  sets[1].maxima = {top_near};  // A second source agrees on the top.
  sets[2].maxima = {bottom};    // Only one source sees the bottom.
  TopologicalPointStats stats;
  const std::vector<TopologicalPoint> points =
      SelectTopologicalPoints(graph_, solver_, sets, &stats);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points[0].votes, 2);
  EXPECT_EQ(points[0].members, (std::vector<int32_t>{std::min(top, top_near),
                                                     std::max(top, top_near)}));
  // The representative is the member farthest from the saddle: the pole.
  EXPECT_EQ(points[0].vertex, top);
  EXPECT_NEAR(points[0].radius, M_PI / 2 + 2.0, 0.1);
  EXPECT_GE(stats.sweeps, 2);
}

TEST_F(CapsuleSets, RadiusStopsTheSearchAtTheNearestSaddle) {
  // Two sources see the top pole; the third sees a maximum beyond the
  // saddle, which must not count towards the top's region.
  const int32_t top = 0;
  const int32_t near_saddle = Nearest({1.0, 0.0, 1.0});
  const int32_t beyond = Nearest({1.0, 0.0, -1.0});
  std::vector<CriticalPoints> sets(3);
  sets[0].saddles = {near_saddle};
  sets[0].maxima = {top};
  sets[1].maxima = {beyond};
  sets[2].maxima = {beyond};
  const std::vector<TopologicalPoint> points =
      SelectTopologicalPoints(graph_, solver_, sets);
  // The top is seen by one source only within its radius: rejected. The
  // maximum beyond the saddle has two sources: accepted.
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points[0].vertex, beyond);
  EXPECT_EQ(points[0].votes, 2);
}

TEST_F(CapsuleSets, NoSaddleMeansTheWholeSurfaceIsOneRegion) {
  std::vector<CriticalPoints> sets(3);
  sets[0].maxima = {0};
  sets[1].maxima = {graph_.num_vertices() - 1};
  sets[2].maxima = {};
  const std::vector<TopologicalPoint> points =
      SelectTopologicalPoints(graph_, solver_, sets);
  ASSERT_EQ(points.size(), 1u);
  EXPECT_EQ(points[0].votes, 2);
  EXPECT_EQ(points[0].radius, kUnreachable);
  EXPECT_EQ(points[0].members.size(), 2u);
  EXPECT_TRUE(SelectTopologicalPoints(graph_, solver_, {}).empty());
}

// Real sets: three analyses on a star give one point per arm, each voted by
// at least two sources, whatever the order of the sets.
TEST(TopologicalPointsTest, StarGivesOnePointPerArm) {
  synth::ShapeOptions o;
  o.target_vertices = 5000;
  absl::StatusOr<Mesh> m = synth::GenerateStar(6, o);
  ASSERT_TRUE(m.ok());
  const MeshGraph graph = MeshGraph::Build(*m);
  const VertexLinks links = VertexLinks::Build(*m);
  DijkstraSolver solver(graph);
  // The paper's sources (4.5): two far points and the surface centre.
  absl::StatusOr<SourcePoints> sp = SelectSourcePoints(graph, solver, {});
  ASSERT_TRUE(sp.ok());
  const int32_t a = sp->far_a, b = sp->far_b, c = sp->centre;
  std::vector<CriticalPoints> sets;
  for (int32_t s : {a, b, c}) {
    absl::StatusOr<CriticalPoints> cp =
        AnalyzeCriticalPoints(graph, links, s, {});
    ASSERT_TRUE(cp.ok());
    sets.push_back(*cp);
  }
  const std::vector<TopologicalPoint> p1 =
      SelectTopologicalPoints(graph, solver, sets);
  std::reverse(sets.begin(), sets.end());
  const std::vector<TopologicalPoint> p2 =
      SelectTopologicalPoints(graph, solver, sets);
  EXPECT_EQ(p1.size(), 6u);
  ASSERT_EQ(p1.size(), p2.size());
  for (size_t i = 0; i < p1.size(); ++i) {
    EXPECT_EQ(p1[i].vertex, p2[i].vertex);
    EXPECT_GE(p1[i].votes, 2);
  }
}

// Oracle for PersistentMaxima, by another algorithm: for a local maximum
// m, the saddle is the highest "lowest point" over all paths from m to a
// vertex above m (a widest-path search), and the persistence is
// field(m) minus it.
double PersistenceByWidestPath(const MeshGraph& graph,
                               const std::vector<double>& field, int32_t m) {
  std::vector<double> best(graph.num_vertices(), -1e300);
  std::priority_queue<std::pair<double, int32_t>> heap;
  best[m] = field[m];
  heap.push({field[m], m});
  while (!heap.empty()) {
    const auto [bottleneck, v] = heap.top();
    heap.pop();
    if (bottleneck < best[v]) continue;
    if (field[v] > field[m]) return field[m] - bottleneck;
    for (int32_t w : graph.neighbors(v)) {
      const double b = std::min(bottleneck, field[w]);
      if (b > best[w]) {
        best[w] = b;
        heap.push({b, w});
      }
    }
  }
  double lowest = field[m];
  for (double f : field) lowest = std::min(lowest, f);
  return field[m] - lowest;  // the highest maximum
}

TEST(PersistentMaximaTest, MatchesWidestPathOracle) {
  synth::ShapeOptions options;
  options.target_vertices = 1500;
  for (const char* name : {"hand", "octopus", "biped_adult"}) {
    absl::StatusOr<Mesh> mesh = synth::GenerateShape(name, 1, options);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    const MeshGraph graph = MeshGraph::Build(*mesh);
    DijkstraSolver solver(graph);
    const std::vector<double> field = solver.Run(0);
    const std::vector<PersistentMaximum> all =
        PersistentMaxima(graph, field, 0.0);
    std::map<int32_t, PersistentMaximum> by_vertex;
    for (const PersistentMaximum& m : all) by_vertex[m.vertex] = m;
    EXPECT_EQ(by_vertex.size(), all.size()) << name;
    int maxima = 0, highest = 0;
    for (int32_t v = 0; v < graph.num_vertices(); ++v) {
      bool is_max = true;
      for (int32_t w : graph.neighbors(v)) is_max &= field[w] < field[v];
      if (!is_max) continue;
      ++maxima;
      ASSERT_EQ(by_vertex.count(v), 1u) << name << " vertex " << v;
      const PersistentMaximum& m = by_vertex[v];
      EXPECT_NEAR(m.persistence, PersistenceByWidestPath(graph, field, v),
                  1e-12)
          << name << " vertex " << v;
      if (m.saddle < 0) {
        ++highest;
      } else {
        EXPECT_DOUBLE_EQ(field[m.saddle], field[v] - m.persistence);
      }
    }
    EXPECT_GE(maxima, 3) << name;
    EXPECT_EQ(highest, 1) << name;  // one component, one maximum never dies
    // Sorted by decreasing persistence; a threshold keeps a prefix.
    for (size_t i = 1; i < all.size(); ++i) {
      EXPECT_GE(all[i - 1].persistence, all[i].persistence);
    }
    const double cut = all.size() > 2 ? all[2].persistence : 0.0;
    const std::vector<PersistentMaximum> kept =
        PersistentMaxima(graph, field, cut);
    for (const PersistentMaximum& m : kept) EXPECT_GE(m.persistence, cut);
    size_t expected = 0;
    for (const PersistentMaximum& m : all) expected += m.persistence >= cut;
    EXPECT_EQ(kept.size(), expected) << name;
  }
}

// SimplifyByPersistence on a star of k arms reaching 0.85 beyond a ball of
// radius 0.35, of radius 0.1 (synth.h): from the tip of one arm, each other
// arm's tip rises about its length less its base's half girth (0.85 - 0.3)
// above the saddle where its wavefront closes, the farthest one above the
// source; the ball's far side and the tessellation's ripples stand far
// lower. A threshold of 0.33 keeps k - 1 maxima and their k - 2 saddles,
// and exactly the other arms' tips.
TEST(PersistentMaximaTest, StarKeepsOneMaximumPerOtherArm) {
  synth::ShapeOptions o;
  o.target_vertices = 5000;
  for (int arms : {3, 5, 6}) {
    absl::StatusOr<synth::Skeleton> sk = synth::StarSkeleton(arms, 0, o);
    ASSERT_TRUE(sk.ok());
    absl::StatusOr<Mesh> m = synth::GenerateStar(arms, o);
    ASSERT_TRUE(m.ok());
    const MeshGraph graph = MeshGraph::Build(*m);
    DijkstraSolver solver(graph);
    absl::StatusOr<SourcePoints> sp = SelectSourcePoints(graph, solver, {});
    ASSERT_TRUE(sp.ok());
    absl::StatusOr<CriticalPoints> cp =
        AnalyzeCriticalPoints(graph, graph.links(), sp->far_a, {});
    ASSERT_TRUE(cp.ok());
    const CriticalPoints simple = SimplifyByPersistence(graph, *cp, 0.33);
    EXPECT_EQ(simple.maxima.size(), static_cast<size_t>(arms - 1)) << arms;
    EXPECT_EQ(simple.saddles.size(), static_cast<size_t>(arms - 2)) << arms;
    EXPECT_EQ(simple.distances, cp->distances);
    EXPECT_EQ(simple.source, cp->source);
    // Each maximum is at an arm's end (leaf bones of the skeleton), a
    // different one each.
    std::vector<Eigen::Vector3d> tips;
    std::vector<int> children(sk->bones.size(), 0);
    for (const synth::Bone& b : sk->bones) {
      if (b.parent >= 0) ++children[b.parent];
    }
    for (size_t i = 0; i < sk->bones.size(); ++i) {
      if (children[i] == 0) tips.push_back(sk->bones[i].end);
    }
    ASSERT_EQ(tips.size(), static_cast<size_t>(arms));
    std::vector<int> hit(arms, 0);
    for (int32_t v : simple.maxima) {
      int best = 0;
      for (int t = 1; t < arms; ++t) {
        if ((m->positions[v] - tips[t]).norm() <
            (m->positions[v] - tips[best]).norm())
          best = t;
      }
      EXPECT_LT((m->positions[v] - tips[best]).norm(), 0.3) << arms;
      ++hit[best];
    }
    for (int h : hit) EXPECT_LE(h, 1) << arms;
  }
}

}  // namespace
}  // namespace tpr::extract
