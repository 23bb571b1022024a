// Topological Ring Extraction (4.6): Eq. 1, merges, Eq. 3 per front,
// termination, regions, on capsules and stars with analytic answers.
#include "extractor/lib/topological_rings.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "extractor/lib/geodesic.h"
#include "extractor/synth/synth.h"
#include "gtest/gtest.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

TEST(RingStartTimesTest, EquationOne) {
  // MAX g_o * (MAX G - G(m)) / (MAX G - MIN G).
  const std::vector<double> s =
      RingStartTimes({10.0, 6.0, 8.0, 12.0}, 2.0, 10.0, 4.0);
  ASSERT_EQ(s.size(), 4u);
  EXPECT_DOUBLE_EQ(s[0], 0.0);
  EXPECT_DOUBLE_EQ(s[1], 2.0);
  EXPECT_DOUBLE_EQ(s[2], 1.0);
  EXPECT_DOUBLE_EQ(s[3], 0.0);  // Above the MAX G estimate: clamped.
  EXPECT_EQ(RingStartTimes({3.0}, 5.0, 5.0, 4.0), std::vector<double>{0.0});
}

// Capsule of length L between caps of radius r along z; poles at the ends.
// Two fronts from the poles, started together, meet at the middle at level
// pi r / 2 + L / 2: both fronts live that long (Eq. 3), and each one's
// wavefront is the middle loop.
TEST(TopologicalRingsTest, CapsuleFrontsMeetInTheMiddle) {
  const Mesh m = testing::Capsule(1.0, 4.0, 120, 32);
  const MeshGraph graph = MeshGraph::Build(m);
  const int32_t top = 0, bottom = graph.num_vertices() - 1;
  RingOptions options;
  options.length_threshold = 1.0;
  absl::StatusOr<RingExtraction> r =
      ExtractTopologicalRings(graph, {top, bottom}, {0.0, 0.0}, {}, options);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->fronts.size(), 3u);  // Two point fronts and their merge.
  const double expected = M_PI / 2 + 2.0;
  for (int f : {0, 1}) {
    EXPECT_EQ(r->fronts[f].parent, 2);
    EXPECT_NEAR(r->fronts[f].death, expected,
                0.1);  // First contact: a ring step early.
    EXPECT_NEAR(r->fronts[f].length, expected, 0.1);
    EXPECT_TRUE(r->fronts[f].is_ring);
    ASSERT_FALSE(r->fronts[f].ring_vertices.empty());
    // The front is a band a few ring steps (0.06) wide around the middle.
    for (int32_t v : r->fronts[f].ring_vertices)
      EXPECT_NEAR(m.positions[v].z(), 0.0, 0.25);
  }
  EXPECT_EQ(r->fronts[2].children, (std::vector<int32_t>{0, 1}));
  EXPECT_EQ(r->fronts[2].points, (std::vector<int32_t>{0, 1}));
  EXPECT_FALSE(r->fronts[2].is_ring);
  // All merged into one: stop right after the merge; the two halves are
  // protrusion regions, FR is what is left (almost nothing).
  EXPECT_EQ(r->live_fronts_at_end, 1);
  EXPECT_FALSE(r->stopped_by_saddles);
  ASSERT_EQ(r->regions.size(), 3u);
  EXPECT_EQ(r->regions[1].kind, RegionKind::kProtrusion);
  EXPECT_EQ(r->regions[2].kind, RegionKind::kProtrusion);
  double total = 0.0;
  for (const Region& reg : r->regions) total += reg.area;
  EXPECT_NEAR(total, graph.total_area(), 1e-9 * graph.total_area());
  EXPECT_NEAR(r->regions[1].area, r->regions[2].area,
              0.05 * graph.total_area());
  EXPECT_LT(r->regions[0].area, 0.05 * graph.total_area());
}

// A later start (Eq. 1) moves the meeting towards the late point: with the
// bottom starting 1.0 later the fronts meet 0.5 below... above the middle,
// at level (pi/2 + 2) + 0.5.
TEST(TopologicalRingsTest, StartTimesShiftTheMeeting) {
  const Mesh m = testing::Capsule(1.0, 4.0, 120, 32);
  const MeshGraph graph = MeshGraph::Build(m);
  absl::StatusOr<RingExtraction> r = ExtractTopologicalRings(
      graph, {0, graph.num_vertices() - 1}, {0.0, 1.0}, {}, RingOptions{});
  ASSERT_TRUE(r.ok());
  EXPECT_NEAR(r->fronts[0].death, M_PI / 2 + 2.5, 0.05);
  EXPECT_NEAR(r->fronts[0].length, M_PI / 2 + 2.5, 0.05);
  EXPECT_NEAR(r->fronts[1].length, M_PI / 2 + 1.5, 0.05);
  for (int32_t v : r->fronts[0].ring_vertices)
    EXPECT_NEAR(m.positions[v].z(), -0.5, 0.25);
}

TEST(TopologicalRingsTest,
     ThresholdDropsShortFrontsAndPointsWithoutStartAreAbsorbed) {
  const Mesh m = testing::Capsule(1.0, 4.0, 120, 32);
  const MeshGraph graph = MeshGraph::Build(m);
  const int32_t top = 0, bottom = graph.num_vertices() - 1;
  RingOptions high;
  high.length_threshold = 100.0;
  absl::StatusOr<RingExtraction> r =
      ExtractTopologicalRings(graph, {top, bottom}, {0.0, 0.0}, {}, high);
  ASSERT_TRUE(r.ok());
  for (const Front& f : r->fronts) EXPECT_FALSE(f.is_ring);
  ASSERT_EQ(r->regions.size(), 1u);  // Only FR.
  for (int32_t reg : r->vertex_region) EXPECT_EQ(reg, 0);

  // A third point in the middle that would start at level 10: the pole
  // fronts reach it first, so it never starts and sweeps nothing.
  int32_t middle = 0;
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if (std::abs(m.positions[v].z()) < std::abs(m.positions[middle].z()))
      middle = v;
  }
  r = ExtractTopologicalRings(graph, {top, bottom, middle}, {0.0, 0.0, 10.0},
                              {}, RingOptions{});
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE(r->fronts[2].started);
  EXPECT_TRUE(r->fronts[0].started && r->fronts[1].started);
  EXPECT_EQ(r->live_fronts_at_end, 1);
}

// Each arm of a star is a protrusion: k point fronts, each a ring where the
// arm meets the ball; the centre saddle shortcut (4.6.3) stops earlier.
TEST(TopologicalRingsTest, StarArmsGiveOneRingEachAndSaddleShortcutStopsEarly) {
  const int arms = 5;
  synth::ShapeOptions o;
  o.target_vertices = 5000;
  absl::StatusOr<Mesh> m = synth::GenerateStar(arms, o);
  absl::StatusOr<synth::Skeleton> sk = synth::StarSkeleton(arms, 0, o);
  ASSERT_TRUE(m.ok() && sk.ok());
  const MeshGraph graph = MeshGraph::Build(*m);
  std::vector<int32_t> tips;
  for (const synth::Bone& b : sk->bones) {
    if (b.name.find("outer") == std::string::npos) continue;
    int32_t best = 0;
    for (int32_t v = 0; v < graph.num_vertices(); ++v) {
      if ((m->positions[v] - b.end).norm() <
          (m->positions[best] - b.end).norm())
        best = v;
    }
    tips.push_back(best);
  }
  ASSERT_EQ(static_cast<int>(tips.size()), arms);
  RingOptions options;
  options.length_threshold = 0.2;
  absl::StatusOr<RingExtraction> r = ExtractTopologicalRings(
      graph, tips, std::vector<double>(arms, 0.0), {}, options);
  ASSERT_TRUE(r.ok());
  int rings = 0;
  for (int i = 0; i < arms; ++i) rings += r->fronts[i].is_ring;
  EXPECT_EQ(rings, arms);
  for (int i = 0; i < arms; ++i) {
    EXPECT_EQ(r->regions[r->front_region[i]].kind, RegionKind::kProtrusion);
    EXPECT_EQ(r->point_region[i], r->front_region[i]);
  }

  // The shortcut: with a vertex half-way along an arm as the only "centre
  // saddle", the sweep stops as soon as that vertex is settled, before the
  // arms' fronts meet.
  Eigen::Vector3d mid = Eigen::Vector3d::Zero();
  for (const synth::Bone& b : sk->bones) {
    if (b.name.find("outer") != std::string::npos) {
      mid = 0.5 * (b.start + b.end);
      break;
    }
  }
  std::vector<int32_t> saddle = {0};
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if ((m->positions[v] - mid).norm() < (m->positions[saddle[0]] - mid).norm())
      saddle[0] = v;
  }
  options.stop_at_centre_saddles = true;
  absl::StatusOr<RingExtraction> early = ExtractTopologicalRings(
      graph, tips, std::vector<double>(arms, 0.0), saddle, options);
  ASSERT_TRUE(early.ok());
  EXPECT_TRUE(early->stopped_by_saddles);
  EXPECT_NEAR(early->final_level, early->level[saddle[0]], 1e-12);
  EXPECT_LT(early->final_level, r->final_level);
  for (const Front& f : early->fronts)
    EXPECT_EQ(f.parent, -1);  // No merge yet.
}

TEST(TopologicalRingsTest, RejectsBadArguments) {
  const Mesh m = testing::Icosphere(1);
  const MeshGraph graph = MeshGraph::Build(m);
  EXPECT_EQ(ExtractTopologicalRings(graph, {0}, {}, {}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ExtractTopologicalRings(graph, {-1}, {0.0}, {}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(ExtractTopologicalRings(graph, {0}, {NAN}, {}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(
      ExtractTopologicalRings(graph, {0}, {0.0}, {100000}, {}).status().code(),
      absl::StatusCode::kInvalidArgument);
  // No point: everything is FR.
  absl::StatusOr<RingExtraction> none =
      ExtractTopologicalRings(graph, {}, {}, {}, {});
  ASSERT_TRUE(none.ok());
  for (int32_t reg : none->vertex_region) EXPECT_EQ(reg, 0);
}

}  // namespace
}  // namespace tpr::extract
