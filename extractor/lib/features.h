// Geometric feature extraction (Tam & Lau 2007, section 5): the generalized
// and normalized integral geodesic of points and rings (Eqs. 4, 5), the
// effective area of every feature (5.2, Eq. 6) and the geometric surface
// vectors over geodesic bands (5.3, Fig. 8).
//
//   std::vector<double> defects = AngleDefects(mesh, links);
//   SurfaceVectors sv = ComputeSurfaceVectors(graph, links, distances, defects,
//                                             /*bands=*/20, total_area);
#ifndef TPR_EXTRACTOR_LIB_FEATURES_H_
#define TPR_EXTRACTOR_LIB_FEATURES_H_

#include <vector>

#include "extractor/lib/critical_points.h"
#include "extractor/lib/geodesic.h"
#include "extractor/lib/mesh.h"
#include "extractor/lib/topological_rings.h"

namespace tpr::extract {

// AngleDefects returns, per vertex, its angle defect: 2 pi minus the sum of
// its triangle angles at an interior vertex, pi minus that sum on the
// boundary (a vertex whose link is a path). The defect is the integral of
// Gaussian curvature over the vertex's area (discrete Gauss-Bonnet), so a
// closed genus-0 mesh sums to 4 pi. Vertices without triangles get 0.
// Precondition: links built from `mesh`. O(f). Thread-safe.
std::vector<double> AngleDefects(const Mesh& mesh, const VertexLinks& links);

// SurfaceVectors are the three geometric surface vectors of one feature
// (5.3), one entry per geodesic band, all scale-free (see signature.h).
struct SurfaceVectors {
  // Segment-area-weighted mean of the segments' integrated Gaussian
  // curvature (radians; scale-free by Gauss-Bonnet).
  std::vector<double> curvature;
  // Segment-area-weighted mean segment area of the band / total area.
  std::vector<double> area;
  // Segment-area-weighted mean segment thickness / sqrt(total area).
  std::vector<double> distance;
};

// ComputeSurfaceVectors divides the vertices reached in `distances` (the
// geodesic distance from a feature) into `bands` bands of equal width from
// 0 to the largest finite distance (the last band closed), splits each band
// into segments (connected by mesh edges inside the band, found by a
// search, 5.3), and gives each band the segment-area-weighted mean over its
// segments of: integrated Gaussian curvature (sum of the segment's angle
// defects, radians: "area-weighted Gaussian curvature" read as the integral
// of K dA, see features.cc for why not the mean K), segment area, and average
// distance (area-weighted mean Euclidean distance of the segment's vertices to
// its area-weighted centre of mass; the weighting keeps the value stable under
// remeshing). Empty bands are 0. Preconditions: bands >= 1; distances, defects
// of size n; total_area > 0. Cost O(n + e). Thread-safe (per-thread scratch,
// reused across calls). With band_extent > 0 the bands divide [0, band_extent]
// instead (vertices farther away fall in the last band), so that band b covers
// the same absolute range for every feature of a mesh.
SurfaceVectors ComputeSurfaceVectors(const MeshGraph& graph,
                                     const VertexLinks& links,
                                     const std::vector<double>& distances,
                                     const std::vector<double>& defects,
                                     int bands, double total_area,
                                     double band_extent = 0.0);

// RingIntegralGeodesic returns G'(U) of a ring U, Eq. 4: the interpolation
// of G(o) and G(w) by the vertex-set geodesic distances g_vs(o, U) and
// g_vs(w, U) (w: the ancestor point, the ring's originating point farthest
// from it). When both distances are 0 returns G(o). Pure.
double RingIntegralGeodesic(double g_vs_o, double g_vs_w, double g_o,
                            double g_w);

// NormalizeIntegralGeodesic returns Eq. 5, (g - g_min) / (g_max - g_min),
// clamped to [0, 1] (MAX G is an estimate); 0 when g_max <= g_min. Pure.
double NormalizeIntegralGeodesic(double g, double g_min, double g_max);

// EffectiveAreas returns the weights of 5.2 (Eq. 6) for the features in
// signature order: the topological points 0..P-1, then the ring fronts of
// `rings` in increasing front id. Each region's area is distributed:
// a PR (a point front's ring region) half to its ring and half to the
// point(s) in it; an SR or FR to its adjacent features in proportion to
// Region(C(l_s)^-) of each (4.6.2): for an adjacent ring, the area of the
// region it bounds from above (for the SR's own ring, the SR itself); for a
// point whose front is not a ring (it merged too early, 4.6.2, and so lies
// inside the SR or FR), the area its own front swept. If those proportions
// are all 0 the region is split equally. The weights are renormalized by
// the distributed area so that they sum to 1 (Eq. 6); a region with no
// adjacent feature (only possible with no feature at all) is left out.
// Returns an empty vector when there is no feature. Precondition: `rings`
// computed on `graph` for `num_points` points. O(n + features). Thread-safe.
std::vector<double> EffectiveAreas(const MeshGraph& graph,
                                   const RingExtraction& rings, int num_points);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_FEATURES_H_
