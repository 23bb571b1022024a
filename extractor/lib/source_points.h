// Source point selection (Tam & Lau 2007, 4.5): the two furthest points by a
// double Dijkstra sweep [14], plus the surface centre (minimum integral
// geodesic, 4.1) found by hierarchical patch search.
//
//   DijkstraSolver solver(graph);
//   absl::StatusOr<SourcePoints> s = SelectSourcePoints(graph, solver, {});
//   RunCriticalPointAnalysis(s->far_a); ... (s->far_b); ... (s->centre);
#ifndef TPR_EXTRACTOR_LIB_SOURCE_POINTS_H_
#define TPR_EXTRACTOR_LIB_SOURCE_POINTS_H_

#include <cstdint>

#include "absl/status/statusor.h"
#include "extractor/lib/geodesic.h"
#include "extractor/lib/integral_geodesic.h"

namespace tpr::extract {

// SourcePoints are the three minima the Critical Point Analysis starts from.
struct SourcePoints {
  // far_a: the vertex farthest from an arbitrary start vertex (the lowest
  // vertex id of the largest component); far_b: the vertex farthest from
  // far_a. Together an approximation of the two furthest points (4.5).
  int32_t far_a = -1;
  int32_t far_b = -1;
  // The surface centre o (4.1, 4.5).
  int32_t centre = -1;
  // g_far_ab: geodesic distance far_a -> far_b (the sweep's maximum).
  double g_far_ab = 0.0;
  // The search result: g_min = G(centre) = MIN G, g_max = MAX G estimate
  // (see SurfaceCentre), sweeps psi.
  SurfaceCentre surface_centre;
  // Sweeps spent in total (2 for the double sweep + the centre search).
  int sweeps = 0;
};

// SelectSourcePoints picks the three source points on the largest component
// (by area) of `graph`; other components are ignored (TPR describes one
// connected surface; the pipeline warns). Errors: INVALID_ARGUMENT for a
// graph without vertices or whose largest component has zero area, or for
// options out of range (first_level_patches < 2, patches_per_level < 1,
// negative thresholds, max_sweeps < 1, field_budget_bytes < 0). Cost: 2 + psi
// Dijkstra sweeps. Not thread-safe per solver.
absl::StatusOr<SourcePoints> SelectSourcePoints(
    const MeshGraph& graph, DijkstraSolver& solver,
    const IntegralGeodesicOptions& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_SOURCE_POINTS_H_
