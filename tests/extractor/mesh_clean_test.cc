// Tests for the cleaning steps (extractor/lib/mesh_clean.h), each on its
// own. Oracles: hand-counted answers on small constructed soups, brute-force
// checks written independently of the library (set-based duplicate and
// manifold checks, Heron areas), and the same soup cleaned in another order.
#include "extractor/lib/mesh_clean.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <map>
#include <set>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "extractor/lib/disjoint_sets.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tpr::extract {
namespace {

using ::testing::HasSubstr;

PolygonSoup Soup(std::vector<Eigen::Vector3d> positions,
                 const std::vector<std::vector<int32_t>>& polygons) {
  PolygonSoup soup;
  soup.positions = std::move(positions);
  for (const auto& p : polygons) soup.AddPolygon(p);
  return soup;
}

// Unit tetrahedron corners, faces outward.
std::vector<Eigen::Vector3d> TetraPositions() {
  return {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
}
const std::vector<std::vector<int32_t>> kTetra = {
    {0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

TEST(ValidatePolygonSoupTest, AcceptsAValidSoupAndNamesEachFault) {
  EXPECT_TRUE(ValidatePolygonSoup(Soup(TetraPositions(), kTetra), {}).ok());
  PolygonSoup far = Soup(TetraPositions(), kTetra);
  far.positions[3].z() = 2 * kMaxCoordinate;
  absl::Status s = ValidatePolygonSoup(far, {});
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("vertex 3: coordinate"));
  EXPECT_THAT(s.message(), HasSubstr("exceeds the supported magnitude"));
  IntakeOptions few;
  few.max_faces = 3;
  s = ValidatePolygonSoup(Soup(TetraPositions(), kTetra), few);
  EXPECT_EQ(s.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(s.message(), HasSubstr("max_faces"));
}

TEST(FanTriangulateTest, SplitsEachPolygonFromItsFirstCorner) {
  PolygonSoup soup =
      Soup({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {-1, 1, 0}},
           {{0, 1, 2, 3, 4}, {0, 1, 2}});
  const Triangles t = FanTriangulate(soup);
  const Triangles expected = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 1, 2}};
  EXPECT_EQ(t, expected);
}

TEST(DropDegenerateTrianglesTest, DropsRepeatedIdsAndCollinearKeepsOrder) {
  const std::vector<Eigen::Vector3d> p = {
      {0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}, {1e-9, 1e-9, 0}};
  Triangles t = {{0, 1, 3}, {0, 0, 1}, {0, 1, 2}, {1, 2, 3}, {0, 4, 1}};
  EXPECT_EQ(DropDegenerateTriangles(p, &t), 2);  // repeated id, collinear
  const Triangles expected = {{0, 1, 3}, {1, 2, 3}, {0, 4, 1}};
  EXPECT_EQ(t, expected);  // a tiny but proper triangle stays (scale-free)
}

TEST(DropDuplicateTrianglesTest, MatchesASetOfSortedTriples) {
  Triangles t = {{0, 1, 2}, {2, 1, 0}, {1, 2, 0},
                 {0, 1, 3}, {3, 1, 0}, {4, 5, 6}};
  std::set<std::array<int32_t, 3>> seen;
  Triangles oracle;
  for (auto tri : t) {
    std::array<int32_t, 3> k = tri;
    std::sort(k.begin(), k.end());
    if (seen.insert(k).second) oracle.push_back(tri);
  }
  EXPECT_EQ(DropDuplicateTriangles(&t), 3);
  EXPECT_EQ(t, oracle);
}

TEST(CheckManifoldTest, NamesTheEdgeOrVertex) {
  Triangles tetra;
  for (const auto& f : kTetra) tetra.push_back({f[0], f[1], f[2]});
  EXPECT_TRUE(CheckManifold(4, tetra).ok());
  Triangles book = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
  absl::Status s = CheckManifold(5, book);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(s.message(), HasSubstr("non-manifold edge (0, 1): shared by 3"));
  Triangles bowtie = {{0, 1, 2}, {0, 3, 4}};
  s = CheckManifold(5, bowtie);
  EXPECT_THAT(s.message(),
              HasSubstr("non-manifold vertex 0: its triangles form 2"));
}

double SignedVolume(const std::vector<Eigen::Vector3d>& p, const Triangles& t) {
  double v = 0;
  for (const auto& f : t) v += p[f[0]].dot(p[f[1]].cross(p[f[2]])) / 6.0;
  return v;
}

TEST(OrientConsistentlyTest, FlipsMinorityAndTurnsClosedSurfacesOutward) {
  const auto p = TetraPositions();
  Triangles t;
  for (const auto& f : kTetra) t.push_back({f[0], f[2], f[1]});  // inward
  t[2] = {0, 3, 2};                                              // one outward
  absl::StatusOr<int64_t> flipped = OrientConsistently(p, &t);
  ASSERT_TRUE(flipped.ok()) << flipped.status();
  EXPECT_EQ(*flipped, 3);
  EXPECT_NEAR(SignedVolume(p, t), 1.0 / 6.0, 1e-12);
  // Every directed edge once: consistent.
  std::set<std::pair<int32_t, int32_t>> directed;
  for (const auto& f : t) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_TRUE(directed.insert({f[k], f[(k + 1) % 3]}).second);
    }
  }
}

TEST(CompactVerticesTest, RemovesUnreferencedKeepingOrder) {
  std::vector<Eigen::Vector3d> p = {
      {0, 0, 0}, {9, 9, 9}, {1, 0, 0}, {0, 1, 0}, {8, 8, 8}};
  Triangles t = {{0, 2, 3}};
  EXPECT_EQ(CompactVertices(&p, &t), 2);
  ASSERT_EQ(p.size(), 3u);
  EXPECT_EQ(p[1], Eigen::Vector3d(1, 0, 0));
  const Triangles expected = {{0, 1, 2}};
  EXPECT_EQ(t, expected);
}

TEST(CleanPolygonSoupTest, RunsTheStepsInOrderWithWarnings) {
  PolygonSoup soup =
      Soup({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {5, 5, 5}},
           {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}, {3, 2, 1}, {0, 0, 1}});
  absl::StatusOr<LoadedMesh> m = CleanPolygonSoup(std::move(soup), {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->stats.faces, 4);
  EXPECT_EQ(m->stats.vertices, 4);
  EXPECT_EQ(m->stats.dropped_degenerate_faces, 1);
  EXPECT_EQ(m->stats.dropped_duplicate_faces, 1);
  EXPECT_EQ(m->stats.unreferenced_vertices, 1);
  EXPECT_EQ(m->stats.genus, 0);
  EXPECT_THAT(m->warnings,
              ::testing::ElementsAre(HasSubstr("1 degenerate"),
                                     HasSubstr("1 duplicate"),
                                     HasSubstr("removed 1 vertices")));
}

TEST(DisjointSetsTest, UnionPicksSmallestLinkPicksGivenRoot) {
  DisjointSets sets(4);
  sets.Union(3, 1);
  EXPECT_EQ(sets.Find(3), 1);
  const int64_t fresh = sets.Add();
  EXPECT_EQ(fresh, 4);
  sets.Link(sets.Find(3), fresh);
  sets.Link(sets.Find(0), fresh);
  EXPECT_EQ(sets.Find(1), 4);
  EXPECT_EQ(sets.Find(0), 4);
  EXPECT_EQ(sets.Find(2), 2);
}

}  // namespace
}  // namespace tpr::extract
