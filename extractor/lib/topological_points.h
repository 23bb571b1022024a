// Topological Point Selection (Tam & Lau 2007, 4.4): vote across the maxima
// that Critical Point Analysis found from several sources; a region around a
// maximum, bounded by the nearest saddle of any source, holds a topological
// point when more than half of the sources have a maximum in it.
//
//   std::vector<CriticalPoints> sets = {cp_a, cp_b, cp_centre};
//   DijkstraSolver solver(graph);
//   std::vector<TopologicalPoint> tips =
//       SelectTopologicalPoints(graph, solver, sets);
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

// TopologicalPointOptions departs from the paper where it is unstable.
struct TopologicalPointOptions {
  // A maximum of source s whose persistence in s's distance field is below
  // this (in the mesh's length unit) does not vote: the field's value at
  // the maximum minus its value at the saddle where the maximum's
  // superlevel component joins a higher one (0-dimensional persistence,
  // Edelsbrunner, Letscher and Zomorodian 2002), i.e. the length of the
  // protrusion it tips. A finger, an ear or a bump of a scan then holds no
  // topological point of its own, whatever the resolution. The paper (4.3,
  // 4.4) filters only by cycle size (n = 1 vertex), which depends on the
  // resolution, not on the size of the protrusion, so such small
  // protrusions win or lose the vote of 4.4 from pose to pose. 0 keeps the
  // paper's behaviour. ExtractSignature passes
  // Options::point_min_prominence x sqrt(total area). Default 0.
  double min_persistence = 0.0;
};

// MaximumPersistence returns, per vertex, the persistence of the maximum
// whose superlevel component the vertex joined when the vertices are added
// in decreasing `field` order (graph adjacency): for a local maximum its
// own persistence, for another vertex that of the maximum above it. The
// highest maximum of a component gets its field value minus the
// component's lowest value. Vertices with kUnreachable get 0.
// Cost O(n log n + e). Thread-safe.
std::vector<double> MaximumPersistence(const MeshGraph& graph,
                                       const std::vector<double>& field);

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
// geodesic (5.1) varies least with the pose. Maxima whose persistence in
// their source's field is below options.min_persistence neither vote nor
// are examined (see TopologicalPointOptions).
// Preconditions: every maximum and saddle is a vertex of `graph`; `solver`
// runs on `graph`. Cost: 1 sweep + one sweep bounded by the radius per
// examined maximum (R x O(n log n + e) overall, 7.3.2), plus one
// MaximumPersistence per set when min_persistence > 0. Not thread-safe per
// solver.
std::vector<TopologicalPoint> SelectTopologicalPoints(
    const MeshGraph& graph, DijkstraSolver& solver,
    const std::vector<CriticalPoints>& sets,
    TopologicalPointStats* stats = nullptr,
    const TopologicalPointOptions& options = {});

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_TOPOLOGICAL_POINTS_H_
