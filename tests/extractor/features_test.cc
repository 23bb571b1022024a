// Geometric features (section 5) against analytic answers: Gauss-Bonnet
// for the angle defects, spherical zones for the band vectors, Eqs. 4-6.
#include "extractor/lib/features.h"

#include <cmath>
#include <numeric>
#include <vector>

#include "extractor/lib/critical_points.h"
#include "extractor/lib/geodesic.h"
#include "extractor/lib/topological_rings.h"
#include "gtest/gtest.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

double Sum(const std::vector<double>& v) {
  return std::accumulate(v.begin(), v.end(), 0.0);
}

TEST(AngleDefectsTest, GaussBonnet) {
  // Closed genus 0: 4 pi.
  for (const Mesh& m :
       {testing::Icosphere(3), testing::Capsule(1.0, 2.0, 40, 24)}) {
    EXPECT_NEAR(Sum(AngleDefects(m, VertexLinks::Build(m))), 4 * M_PI, 1e-9);
  }
  // An open cylinder (Euler characteristic 0): interior vertices are flat,
  // and all defects sum to 0.
  const Mesh tube = testing::Tube(1.0, 3.0, 20, 24);
  const VertexLinks links = VertexLinks::Build(tube);
  const std::vector<double> d = AngleDefects(tube, links);
  EXPECT_NEAR(Sum(d), 0.0, 1e-9);
  for (int32_t v = 0; v < links.num_vertices(); ++v) {
    if ((links.link_end(v) - links.link_begin(v)) / 2 == links.degree(v)) {
      EXPECT_NEAR(d[v], 0.0, 1e-9);
    }
  }
}

// From the pole of a sphere of radius R the bands are zones: constant
// Gaussian curvature 1/R^2 (integrated over a zone: its area / R^2), area
// 2 pi R^2 (cos a - cos b) over geodesic radii [a R, b R], one segment
// each, thickness about R sin(theta) at the zone's middle.
TEST(SurfaceVectorsTest, SphereZonesMatchAnalyticValues) {
  const double radius = 2.0;
  const Mesh m = testing::Icosphere(5, radius);
  const MeshGraph graph = MeshGraph::Build(m);
  const VertexLinks links = VertexLinks::Build(m);
  DijkstraSolver solver(graph);
  int32_t pole = 0;
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if (m.positions[v].z() > m.positions[pole].z()) pole = v;
  }
  const std::vector<double>& d = solver.Run(pole);
  const int bands = 10;
  const SurfaceVectors sv = ComputeSurfaceVectors(
      graph, links, d, AngleDefects(m, links), bands, graph.total_area());
  ASSERT_EQ(sv.curvature.size(), 10u);
  const double max_d = *std::max_element(d.begin(), d.end());
  for (int b = 1; b + 1 < bands; ++b) {
    // Zone in polar angle, using the graph's own largest distance as pi.
    const double t0 = M_PI * b / bands, t1 = M_PI * (b + 1) / bands;
    const double zone =
        2 * M_PI * radius * radius * (std::cos(t0) - std::cos(t1));
    const double zone_curvature = zone / (radius * radius);  // Gauss-Bonnet
    EXPECT_NEAR(sv.curvature[b], zone_curvature, 0.1 * zone_curvature) << b;
    EXPECT_NEAR(sv.area[b], zone / graph.total_area(),
                0.1 * zone / graph.total_area())
        << b;
    const double thickness = radius * std::sin(0.5 * (t0 + t1));
    EXPECT_NEAR(sv.distance[b] * std::sqrt(graph.total_area()), thickness,
                0.08 * radius)
        << b;
  }
  EXPECT_NEAR(max_d, M_PI * radius, 0.02 * M_PI * radius);
}

// Scale-free: the vectors of a scaled copy are the same.
TEST(SurfaceVectorsTest, InvariantUnderUniformScale) {
  Mesh m = testing::Dumbbell(1.0, 0.7, 0.3, 1.5, 80, 24);
  Mesh big = m;
  for (auto& p : big.positions) p = 3.7 * p + Eigen::Vector3d(1, -2, 5);
  SurfaceVectors out[2];
  int i = 0;
  for (const Mesh* mesh : {&m, &big}) {
    const MeshGraph graph = MeshGraph::Build(*mesh);
    const VertexLinks links = VertexLinks::Build(*mesh);
    DijkstraSolver solver(graph);
    out[i++] = ComputeSurfaceVectors(graph, links, solver.Run(0),
                                     AngleDefects(*mesh, links), 20,
                                     graph.total_area());
  }
  for (int b = 0; b < 20; ++b) {
    EXPECT_NEAR(out[0].curvature[b], out[1].curvature[b], 1e-9);
    EXPECT_NEAR(out[0].area[b], out[1].area[b], 1e-9);
    EXPECT_NEAR(out[0].distance[b], out[1].distance[b], 1e-9);
  }
}

// From the neck loop of a symmetric dumbbell each band has two mirror
// segments, one per ball: the area entry is the segment-area-weighted mean
// of segment areas, half the band's area, not the band's area (5.3).
TEST(SurfaceVectorsTest, BandsSplitIntoSegmentsByConnectivity) {
  const Mesh m =
      testing::Dumbbell(1.0, 1.0, 0.3, 1.5, 120, 24);  // Ring 60 at z = 0.
  const MeshGraph graph = MeshGraph::Build(m);
  const VertexLinks links = VertexLinks::Build(m);
  DijkstraSolver solver(graph);
  std::vector<int32_t> neck;
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if (std::abs(m.positions[v].z()) < 1e-6) neck.push_back(v);
  }
  ASSERT_FALSE(neck.empty());
  const std::vector<double>& d = solver.Run(neck);
  const int bands = 8;
  const SurfaceVectors sv = ComputeSurfaceVectors(
      graph, links, d, AngleDefects(m, links), bands, graph.total_area());
  // Oracle: the band's total area by the same binning.
  const double max_d = *std::max_element(d.begin(), d.end());
  std::vector<double> band_area(bands, 0.0);
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    const int b = std::min(bands - 1, static_cast<int>(d[v] / max_d * bands));
    band_area[b] += graph.vertex_areas()[v];
  }
  for (int b = 1; b < bands; ++b) {
    EXPECT_NEAR(sv.area[b], 0.5 * band_area[b] / graph.total_area(),
                0.03 * band_area[b] / graph.total_area())
        << b;
  }
}

TEST(IntegralGeodesicTest, EquationsFourAndFive) {
  // Eq. 4: a ring a quarter of the way from o to w.
  EXPECT_DOUBLE_EQ(RingIntegralGeodesic(1.0, 3.0, 10.0, 30.0),
                   (1.0 * 30 + 3.0 * 10) / 4.0);
  EXPECT_DOUBLE_EQ(RingIntegralGeodesic(0.0, 5.0, 10.0, 30.0),
                   10.0);  // Ring through o.
  EXPECT_DOUBLE_EQ(RingIntegralGeodesic(0.0, 0.0, 10.0, 30.0), 10.0);
  // Eq. 5.
  EXPECT_DOUBLE_EQ(NormalizeIntegralGeodesic(15.0, 10.0, 30.0), 0.25);
  EXPECT_DOUBLE_EQ(NormalizeIntegralGeodesic(35.0, 10.0, 30.0), 1.0);
  EXPECT_DOUBLE_EQ(NormalizeIntegralGeodesic(5.0, 10.0, 30.0), 0.0);
  EXPECT_DOUBLE_EQ(NormalizeIntegralGeodesic(5.0, 10.0, 10.0), 0.0);
}

// Eq. 6 on a capsule with both pole fronts as rings: PR halves to point and
// ring, FR to the two rings in proportion to their regions.
TEST(EffectiveAreasTest, ProtrusionRegionsAndFinalRegion) {
  const Mesh m = testing::Capsule(1.0, 4.0, 120, 32);
  const MeshGraph graph = MeshGraph::Build(m);
  const int32_t top = 0, bottom = graph.num_vertices() - 1;
  RingOptions options;
  options.length_threshold = 1.0;
  // The bottom starts later, so the two protrusion regions differ.
  absl::StatusOr<RingExtraction> r =
      ExtractTopologicalRings(graph, {top, bottom}, {0.0, 0.6}, {}, options);
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->regions.size(), 3u);
  const std::vector<double> w = EffectiveAreas(graph, *r, 2);
  ASSERT_EQ(w.size(), 4u);  // Two points, then two rings.
  const double a_top = r->regions[r->front_region[0]].area;
  const double a_bot = r->regions[r->front_region[1]].area;
  const double a_fr = r->regions[0].area;
  const double total = a_top + a_bot + a_fr;
  EXPECT_NEAR(total, graph.total_area(), 1e-9);
  EXPECT_NEAR(w[0], 0.5 * a_top / total, 1e-12);
  EXPECT_NEAR(w[1], 0.5 * a_bot / total, 1e-12);
  EXPECT_NEAR(w[2], (0.5 * a_top + a_fr * a_top / (a_top + a_bot)) / total,
              1e-12);
  EXPECT_NEAR(w[3], (0.5 * a_bot + a_fr * a_bot / (a_top + a_bot)) / total,
              1e-12);
  EXPECT_NEAR(Sum(w), 1.0, 1e-12);
  EXPECT_GT(w[0], w[1]);
}

// No ring at all: FR holds everything and goes to the points in proportion
// to the area each one's front swept.
TEST(EffectiveAreasTest, OnlyFinalRegion) {
  const Mesh m = testing::Capsule(1.0, 4.0, 120, 32);
  const MeshGraph graph = MeshGraph::Build(m);
  RingOptions high;
  high.length_threshold = 1e9;
  absl::StatusOr<RingExtraction> r = ExtractTopologicalRings(
      graph, {0, graph.num_vertices() - 1}, {0.0, 0.5}, {}, high);
  ASSERT_TRUE(r.ok());
  std::vector<double> swept(2, 0.0);
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if (r->owner[v] == 0 || r->owner[v] == 1)
      swept[r->owner[v]] += graph.vertex_areas()[v];
  }
  const std::vector<double> w = EffectiveAreas(graph, *r, 2);
  ASSERT_EQ(w.size(), 2u);
  EXPECT_NEAR(w[0], swept[0] / (swept[0] + swept[1]), 1e-12);
  EXPECT_NEAR(w[1], swept[1] / (swept[0] + swept[1]), 1e-12);
  // No point, no ring: no feature, no weight.
  absl::StatusOr<RingExtraction> none =
      ExtractTopologicalRings(graph, {}, {}, {}, high);
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(EffectiveAreas(graph, *none, 0).empty());
}

}  // namespace
}  // namespace tpr::extract
