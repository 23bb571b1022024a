// Topological Point Selection (Tam & Lau 2007, 4.4): vote across the maxima
// that Critical Point Analysis found from several sources; a region around a
// maximum, bounded by the nearest saddle of any source, holds a topological
// point when more than half of the sources have a maximum in it.
//
//   std::vector<CriticalPoints> sets = {cp_a, cp_b, cp_centre};
//   DijkstraSolver solver(graph);
//   std::vector<TopologicalPoint> tips = SelectTopologicalPoints(graph, solver, sets);
#ifndef TPR_EXTRACTOR_LIB_TOPOLOGICAL_POINTS_H_
#define TPR_EXTRACTOR_LIB_TOPOLOGICAL_POINTS_H_

#include <cstdint>
#include <vector>

#include "extractor/lib/critical_points.h"
#include "extractor/lib/geodesic.h"

namespace tpr::extract {

// TopologicalPoint is one validated protrusion tip.
struct TopologicalPoint {
  // The representative vertex (see SelectTopologicalPoints).
  int32_t vertex = -1;
  // Number of sources with a maximum in the region (> sources / 2).
  int votes = 0;
  // Search radius: geodesic distance from the examined maximum to the
  // nearest saddle of any source (kUnreachable when there is no saddle).
  double radius = 0.0;
  // Every maximum (of any source) inside the region, the representative
  // included.
  std::vector<int32_t> members;
};

// TopologicalPointStats reports the cost of one selection (Table 4: R).
struct TopologicalPointStats {
  int sweeps = 0;  // Bounded and unbounded Dijkstra sweeps run.
  int64_t vertices_visited = 0;
};

// SelectTopologicalPoints returns the topological points, in the order they
// were validated. Maxima are examined in decreasing distance to the nearest
// saddle (the most prominent tip first), so the result does not depend on
// the order of `sets`. For an unvisited maximum m the region is the
// geodesic ball around m whose radius is the distance from m to the nearest
// saddle in any set (one multi-source sweep from all saddles gives it for
// every m). The sources with a maximum in the ball are counted; when more
// than sets.size() / 2 have one, the region holds a topological point and
// all its maxima are marked visited; otherwise only m is. The paper picks
// the representative "arbitrarily" (4.4); we take the member maximum
// farthest from any saddle, the tip of the protrusion, so that its integral
// geodesic (5.1) varies least with the pose.
// Preconditions: every maximum and saddle is a vertex of `graph`; `solver`
// runs on `graph`. Cost: 1 sweep + one sweep bounded by the radius per
// examined maximum (R x O(n log n + e) overall, 7.3.2). Not thread-safe per
// solver.
std::vector<TopologicalPoint> SelectTopologicalPoints(
    const MeshGraph& graph, DijkstraSolver& solver,
    const std::vector<CriticalPoints>& sets, TopologicalPointStats* stats = nullptr);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_TOPOLOGICAL_POINTS_H_
