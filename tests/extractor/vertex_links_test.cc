// Tests of the one 1-ring structure (vertex_links.h) against brute force
// over the triangles, on a family of meshes (closed, with boundary, several
// components), and that MeshGraph serves the same structure.
#include "extractor/lib/vertex_links.h"

#include <algorithm>
#include <set>
#include <utility>
#include <vector>

#include "extractor/lib/geodesic.h"
#include "gtest/gtest.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

std::vector<Mesh> Family() {
  return {testing::Icosphere(2), testing::Tube(1.0, 2.0, 4, 12),
          testing::Rectangle(2.0, 1.0, 5, 3),
          testing::Union(testing::Icosphere(1), testing::Tube(0.5, 1.0, 3, 8))};
}

// Brute force: the neighbours of v and the link edges (a, b) of the
// triangles (v, a, b), scanning every triangle.
std::set<int32_t> OracleNeighbours(const Mesh& m, int32_t v) {
  std::set<int32_t> out;
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) {
      if (t[k] == v) {
        out.insert(t[(k + 1) % 3]);
        out.insert(t[(k + 2) % 3]);
      }
    }
  }
  return out;
}

std::multiset<std::pair<int32_t, int32_t>> OracleLinkEdges(const Mesh& m,
                                                           int32_t v) {
  std::multiset<std::pair<int32_t, int32_t>> out;
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) {
      if (t[k] == v) out.insert({t[(k + 1) % 3], t[(k + 2) % 3]});
    }
  }
  return out;
}

TEST(VertexLinksTest, NeighboursLinkEdgesAndFansMatchTheTriangles) {
  for (const Mesh& m : Family()) {
    const VertexLinks links = VertexLinks::Build(m);
    ASSERT_EQ(links.num_vertices(), static_cast<int32_t>(m.positions.size()));
    for (int32_t v = 0; v < links.num_vertices(); ++v) {
      const std::set<int32_t> nb = OracleNeighbours(m, v);
      EXPECT_EQ(std::vector<int32_t>(links.neighbors_begin(v),
                                     links.neighbors_end(v)),
                std::vector<int32_t>(nb.begin(), nb.end()))
          << v;
      std::multiset<std::pair<int32_t, int32_t>> edges;
      for (const int32_t* p = links.link_begin(v); p != links.link_end(v);
           p += 2) {
        edges.insert({p[0], p[1]});
      }
      EXPECT_EQ(edges, OracleLinkEdges(m, v)) << v;
      // The fan holds the same vertices, each once; consecutive entries
      // share a triangle with v (checked in fan order by geodesic_test).
      std::vector<int32_t> fan(links.fan(v).begin(), links.fan(v).end());
      std::sort(fan.begin(), fan.end());
      EXPECT_EQ(fan, std::vector<int32_t>(nb.begin(), nb.end())) << v;
      for (size_t i = 0; i + 1 < links.fan(v).size(); ++i) {
        const int32_t a = links.fan(v)[i];
        const int32_t b = links.fan(v)[i + 1];
        EXPECT_TRUE(edges.count({a, b}) == 1) << v << ": " << a << " -> " << b;
      }
    }
  }
}

TEST(VertexLinksTest, MeshGraphServesTheSameStructure) {
  for (const Mesh& m : Family()) {
    const VertexLinks links = VertexLinks::Build(m);
    for (bool unfold : {false, true}) {
      const MeshGraph graph = MeshGraph::Build(m, {unfold});
      ASSERT_EQ(graph.links().num_vertices(), links.num_vertices());
      for (int32_t v = 0; v < links.num_vertices(); ++v) {
        const auto ring = graph.one_ring(v);
        EXPECT_EQ(
            std::vector<int32_t>(ring.begin(), ring.end()),
            std::vector<int32_t>(links.fan(v).begin(), links.fan(v).end()));
        EXPECT_EQ(std::vector<int32_t>(graph.links().link_begin(v),
                                       graph.links().link_end(v)),
                  std::vector<int32_t>(links.link_begin(v), links.link_end(v)));
        EXPECT_EQ(graph.links().degree(v), links.degree(v));
      }
    }
  }
}

// A degenerate triangle (intake drops them, Build does not require it)
// puts a vertex into its own link: its neighbours include it, as the
// oracle's, while its fan never does.
TEST(VertexLinksTest, DegenerateTriangleKeepsTheVertexInItsOwnNeighbours) {
  Mesh m;
  m.positions.assign(4, Eigen::Vector3d::Zero());
  m.triangles = {{0, 1, 2}, {0, 2, 3}, {2, 2, 3}};
  const VertexLinks links = VertexLinks::Build(m);
  for (int32_t v = 0; v < links.num_vertices(); ++v) {
    const std::set<int32_t> nb = OracleNeighbours(m, v);
    EXPECT_EQ(
        std::vector<int32_t>(links.neighbors_begin(v), links.neighbors_end(v)),
        std::vector<int32_t>(nb.begin(), nb.end()))
        << v;
    std::set<int32_t> without_self = nb;
    without_self.erase(v);
    std::vector<int32_t> fan(links.fan(v).begin(), links.fan(v).end());
    std::sort(fan.begin(), fan.end());
    EXPECT_EQ(fan,
              std::vector<int32_t>(without_self.begin(), without_self.end()))
        << v;
  }
  EXPECT_EQ(links.degree(2), 4);  // 0, 1, 3 and 2 itself
}

TEST(VertexLinksTest, EmptyMeshHasNoVertices) {
  EXPECT_EQ(VertexLinks::Build(Mesh{}).num_vertices(), 0);
  EXPECT_EQ(VertexLinks().num_vertices(), 0);
}

}  // namespace
}  // namespace tpr::extract
