// Tests for the repair of non-manifold input (mesh_clean.h
// RepairNonManifold, through BuildMesh and the file readers): constructed
// cases repaired into meshes that an independent check below finds edge-
// and vertex-manifold and consistently oriented, with counts worked out by
// hand; and every dev mesh in ../shared read without error.
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "extractor/lib/mesh.h"
#include "extractor/lib/mesh_clean.h"
#include "extractor/lib/mesh_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tpr::extract {
namespace {

using ::testing::Contains;
using ::testing::HasSubstr;

const std::string kDir = std::string(TPR_TEST_DATA_DIR) + "/meshes/";

// The independent check, written from the definitions rather than from the
// library's union-find over corners:
//  - edge-manifold and oriented: every directed edge at most once, so every
//    undirected edge has at most two triangles, traversed oppositely;
//  - vertex-manifold: the link of every vertex (the edges opposite it in its
//    triangles) is one simple path or one simple cycle.
// Returns "" when manifold, else what is wrong.
std::string ManifoldFault(const Mesh& mesh) {
  std::set<std::pair<int32_t, int32_t>> directed;
  std::map<std::pair<int32_t, int32_t>, int> undirected;
  std::map<int32_t, std::vector<std::pair<int32_t, int32_t>>> link;
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const int32_t a = t[k], b = t[(k + 1) % 3], c = t[(k + 2) % 3];
      if (!directed.insert({a, b}).second) {
        return "directed edge repeated (inconsistent or 3+ triangles)";
      }
      if (++undirected[{std::min(a, b), std::max(a, b)}] > 2) {
        return "edge with 3+ triangles";
      }
      link[a].push_back({b, c});
    }
  }
  for (const auto& [v, edges] : link) {
    std::map<int32_t, std::vector<int32_t>> adj;
    for (const auto& [a, b] : edges) {
      adj[a].push_back(b);
      adj[b].push_back(a);
    }
    int ends = 0;
    for (const auto& [u, n] : adj) {
      if (n.size() > 2)
        return "vertex " + std::to_string(v) + ": link branches";
      if (n.size() == 1) ++ends;
    }
    // Connected?
    std::set<int32_t> seen{adj.begin()->first};
    std::vector<int32_t> stack{adj.begin()->first};
    while (!stack.empty()) {
      const int32_t u = stack.back();
      stack.pop_back();
      for (int32_t w : adj[u]) {
        if (seen.insert(w).second) stack.push_back(w);
      }
    }
    if (seen.size() != adj.size()) {
      return "vertex " + std::to_string(v) + ": link in several pieces";
    }
    if (ends != 0 && ends != 2) return "vertex " + std::to_string(v) + ": link";
  }
  return "";
}

std::vector<std::vector<int32_t>> Tris(const Mesh& mesh) {
  std::vector<std::vector<int32_t>> out;
  for (const auto& t : mesh.triangles) out.push_back({t[0], t[1], t[2]});
  return out;
}

TEST(ManifoldFaultTest, TheOracleSeesTheFaults) {
  Mesh bowtie;
  bowtie.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}};
  bowtie.triangles = {{0, 1, 2}, {0, 3, 4}};
  EXPECT_THAT(ManifoldFault(bowtie), HasSubstr("vertex 0"));
  Mesh book;
  book.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}};
  book.triangles = {{0, 1, 2}, {1, 0, 3}, {1, 0, 4}};
  EXPECT_NE(ManifoldFault(book), "");
}

// Unit tetrahedron, faces outward.
const std::vector<Eigen::Vector3d> kTetraV = {
    {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
const std::vector<std::vector<int32_t>> kTetraF = {
    {0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

struct Case {
  const char* name;
  std::vector<Eigen::Vector3d> v;
  std::vector<std::vector<int32_t>> f;
  // Expected after repair.
  int64_t vertices, faces, components, boundary_edges, genus;
  int64_t non_manifold_edges, non_manifold_vertices, orientation_cuts;
};

void Cube(const Eigen::Vector3d& o, int32_t base,
          std::vector<Eigen::Vector3d>* v,
          std::vector<std::vector<int32_t>>* f) {
  for (int z = 0; z < 2; ++z)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 2; ++x) v->push_back(o + Eigen::Vector3d(x, y, z));
  auto id = [&](int x, int y, int z) { return base + x + 2 * y + 4 * z; };
  const std::vector<std::array<int32_t, 4>> quads = {
      {id(0, 0, 0), id(0, 1, 0), id(1, 1, 0), id(1, 0, 0)},   // z = 0
      {id(0, 0, 1), id(1, 0, 1), id(1, 1, 1), id(0, 1, 1)},   // z = 1
      {id(0, 0, 0), id(1, 0, 0), id(1, 0, 1), id(0, 0, 1)},   // y = 0
      {id(0, 1, 0), id(0, 1, 1), id(1, 1, 1), id(1, 1, 0)},   // y = 1
      {id(0, 0, 0), id(0, 0, 1), id(0, 1, 1), id(0, 1, 0)},   // x = 0
      {id(1, 0, 0), id(1, 1, 0), id(1, 1, 1), id(1, 0, 1)}};  // x = 1
  for (const auto& q : quads) {
    f->push_back({q[0], q[1], q[2]});
    f->push_back({q[0], q[2], q[3]});
  }
}

std::vector<Case> Cases() {
  std::vector<Case> cases;
  // Bowtie: two triangles pinched at vertex 0. One vertex split, one copy.
  cases.push_back({"bowtie",
                   {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}},
                   {{0, 1, 2}, {0, 3, 4}},
                   6,
                   2,
                   2,
                   6,
                   0,
                   0,
                   1,
                   0});
  // Three triangles on edge (0, 1): the edge is cut; both ends fall into
  // three fans each (2 + 2 copies). Three separate triangles.
  cases.push_back({"three_on_one_edge",
                   {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}},
                   {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}},
                   9,
                   3,
                   3,
                   9,
                   0,
                   1,
                   2,
                   0});
  // A fin standing on an edge of a closed tetrahedron: the fin comes off
  // (ends 0 and 1 split once each); the tetrahedron stays closed.
  {
    Case c{"fin", kTetraV, kTetraF, 7, 5, 2, 3, 0, 1, 2, 0};
    c.v.push_back({0.5, -1, 0.5});
    c.f.push_back({0, 1, 4});
    cases.push_back(c);
  }
  // Two closed cubes sharing an edge (x = y = 1): two closed cubes again.
  {
    Case c{"two_cubes_sharing_an_edge", {}, {}, 16, 24, 2, 0, 0, 1, 2, 0};
    Cube({0, 0, 0}, 0, &c.v, &c.f);
    Cube({1, 1, 0}, 8, &c.v, &c.f);
    // Weld cube B's copies of the shared edge's ends onto cube A's.
    for (auto& t : c.f) {
      for (auto& i : t) {
        if (i == 8) i = 3;      // (1,1,0)
        if (i == 8 + 4) i = 7;  // (1,1,1)
      }
    }
    cases.push_back(c);
  }
  // Moebius strip of 6 quads: cut open along one edge into a twisted band
  // that is a disk (one boundary loop of 12 + 2 edges), both ends split.
  {
    Case c{"moebius_strip", {}, {}, 14, 12, 1, 14, 0, 0, 2, 1};
    const int n = 6;
    for (int i = 0; i < n; ++i) {
      const double a = 2 * M_PI * i / n, t = a / 2;
      for (double s : {-0.3, 0.3}) {
        c.v.emplace_back((1 + s * std::cos(t)) * std::cos(a),
                         (1 + s * std::cos(t)) * std::sin(a), s * std::sin(t));
      }
    }
    for (int i = 0; i + 1 < n; ++i) {
      c.f.push_back({2 * i, 2 * i + 1, 2 * i + 3});
      c.f.push_back({2 * i, 2 * i + 3, 2 * i + 2});
    }
    c.f.push_back({2 * (n - 1), 2 * (n - 1) + 1, 0});  // glued with a twist
    c.f.push_back({2 * (n - 1), 0, 1});
    cases.push_back(c);
  }
  return cases;
}

TEST(RepairNonManifoldTest, ConstructedCasesBecomeManifoldWithTheRightCounts) {
  for (const Case& c : Cases()) {
    SCOPED_TRACE(c.name);
    // The input really is faulty (the oracle agrees with the premise).
    Mesh input;
    input.positions = c.v;
    for (const auto& t : c.f) input.triangles.push_back({t[0], t[1], t[2]});
    EXPECT_NE(ManifoldFault(input), "");

    absl::StatusOr<LoadedMesh> m = BuildMesh(c.v, c.f, {});
    ASSERT_TRUE(m.ok()) << m.status();
    EXPECT_EQ(ManifoldFault(m->mesh), "");
    EXPECT_EQ(m->stats.vertices, c.vertices);
    EXPECT_EQ(m->stats.faces, c.faces);
    EXPECT_EQ(m->stats.components, c.components);
    EXPECT_EQ(m->stats.boundary_edges, c.boundary_edges);
    EXPECT_EQ(m->stats.genus, c.genus);
    EXPECT_EQ(m->stats.non_manifold_edges, c.non_manifold_edges);
    EXPECT_EQ(m->stats.non_manifold_vertices, c.non_manifold_vertices);
    EXPECT_EQ(m->stats.orientation_cuts, c.orientation_cuts);
    EXPECT_THAT(
        m->warnings,
        Contains(HasSubstr("repaired non-manifold input by splitting")));
    EXPECT_THAT(
        m->warnings,
        Contains(HasSubstr(std::to_string(c.non_manifold_edges) +
                           " edges shared by 3 or more triangles, " +
                           std::to_string(c.non_manifold_vertices) +
                           " vertices whose triangles form 2 or more")));
    // No triangle lost, and each output triangle is an input triangle at
    // the same positions (up to orientation).
    std::multiset<std::array<double, 9>> in, out;
    auto key = [](const std::vector<Eigen::Vector3d>& p,
                  std::array<int32_t, 3> t) {
      std::array<std::array<double, 3>, 3> c3;
      for (int k = 0; k < 3; ++k)
        c3[k] = {p[t[k]].x(), p[t[k]].y(), p[t[k]].z()};
      std::sort(c3.begin(), c3.end());
      std::array<double, 9> k9;
      for (int k = 0; k < 9; ++k) k9[k] = c3[k / 3][k % 3];
      return k9;
    };
    for (const auto& t : input.triangles) in.insert(key(c.v, t));
    for (const auto& t : m->mesh.triangles)
      out.insert(key(m->mesh.positions, t));
    EXPECT_EQ(in, out);
  }
}

TEST(RepairNonManifoldTest, ClosedPartsStayClosedAndFaceOutward) {
  for (const Case& c : Cases()) {
    if (std::string(c.name) != "two_cubes_sharing_an_edge" &&
        std::string(c.name) != "fin") {
      continue;
    }
    absl::StatusOr<LoadedMesh> m = BuildMesh(c.v, c.f, {});
    ASSERT_TRUE(m.ok()) << m.status();
    double volume = 0;
    for (const auto& t : m->mesh.triangles) {
      volume += m->mesh.positions[t[0]].dot(
                    m->mesh.positions[t[1]].cross(m->mesh.positions[t[2]])) /
                6.0;
    }
    // Two unit cubes, or the tetrahedron (1/6) plus a flat fin (0).
    EXPECT_NEAR(volume, c.faces == 24 ? 2.0 : 1.0 / 6.0, 1e-12) << c.name;
  }
}

TEST(RepairNonManifoldTest, ManifoldInputIsLeftAlone) {
  absl::StatusOr<LoadedMesh> m = BuildMesh(kTetraV, kTetraF, {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->mesh.positions, kTetraV);
  EXPECT_EQ(Tris(m->mesh), kTetraF);
  EXPECT_TRUE(m->warnings.empty());
  EXPECT_EQ(m->stats.non_manifold_edges + m->stats.non_manifold_vertices +
                m->stats.orientation_cuts,
            0);
}

TEST(RepairNonManifoldTest, FilesThatWereRefusedAreRepaired) {
  // These two files used to be INVALID_ARGUMENT ("non-manifold edge (0, 1):
  // shared by 3 triangles", "non-manifold vertex 0: ... 2 separate fans").
  absl::StatusOr<LoadedMesh> edge =
      LoadMeshFromFile(kDir + "good/nonmanifold_edge.off", {});
  ASSERT_TRUE(edge.ok()) << edge.status();
  EXPECT_EQ(ManifoldFault(edge->mesh), "");
  EXPECT_EQ(edge->stats.non_manifold_edges, 1);
  EXPECT_EQ(edge->stats.faces, 3);
  EXPECT_EQ(edge->stats.components, 3);
  absl::StatusOr<LoadedMesh> vertex =
      LoadMeshFromFile(kDir + "good/nonmanifold_vertex.off", {});
  ASSERT_TRUE(vertex.ok()) << vertex.status();
  EXPECT_EQ(ManifoldFault(vertex->mesh), "");
  EXPECT_EQ(vertex->stats.non_manifold_vertices, 1);
  EXPECT_EQ(vertex->stats.components, 2);  // two tetrahedra touching at 0
  EXPECT_EQ(vertex->stats.boundary_edges, 0);
  EXPECT_EQ(vertex->stats.vertices, 8);
}

// Every dev mesh (SHREC'07 watertight, 400; SHREC'11 simplified, 600) reads
// without error and comes out manifold. About 10 s of CPU; skipped when the
// data is absent. TPR_SHARED_DIR in the environment overrides the build's.
TEST(DevMeshesTest, EveryDevMeshIsRead) {
  const char* env = std::getenv("TPR_SHARED_DIR");
  const std::string shared = env != nullptr ? env : TPR_SHARED_DIR;
  int read = 0;
  for (const char* set : {"shrec07-watertight", "shrec11-simplified"}) {
    const std::string dir = shared + "/data/" + set;
    std::ifstream manifest(dir + "/MANIFEST.txt");
    if (!manifest) continue;
    std::string path, label;
    while (manifest >> path >> label) {
      absl::StatusOr<LoadedMesh> m = LoadMeshFromFile(dir + "/" + path, {});
      ASSERT_TRUE(m.ok()) << set << "/" << path << ": " << m.status();
      EXPECT_GT(m->stats.faces, 0);
      ++read;
    }
  }
  if (read == 0) GTEST_SKIP() << "no dev data under " << shared << "/data";
  EXPECT_EQ(read, 1000);
}

}  // namespace
}  // namespace tpr::extract
