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

// PersistentMaximum is a local maximum of a scalar field with its
// 0-dimensional persistence pair (Edelsbrunner, Letscher and Zomorodian
// 2002): adding vertices in decreasing field order, the superlevel component
// born at `vertex` dies at `saddle`, where it joins a component born higher.
struct PersistentMaximum {
  int32_t vertex = -1;
  // The merge vertex; -1 for the highest maximum of a connected component,
  // which never dies.
  int32_t saddle = -1;
  // field[vertex] - field[saddle]; for the highest maximum of a component,
  // field[vertex] minus the component's lowest value. In the field's unit:
  // for a geodesic distance field, the length of the protrusion the maximum
  // tips, measured from where it branches off.
  double persistence = 0.0;
};

// PersistentMaxima returns the local maxima of `field` (graph adjacency:
// every neighbour strictly lower, ties broken by vertex id) whose
// persistence is at least min_persistence, in decreasing persistence (ties
// by vertex id). Vertices with kUnreachable are left out. Deterministic.
// Cost O(n log n + e). Thread-safe.
std::vector<PersistentMaximum> PersistentMaxima(
    const MeshGraph& graph, const std::vector<double>& field,
    double min_persistence);

// SimplifyByPersistence returns `set` with its maxima and saddles replaced
// by the persistent pairs of its own distance field: the maxima of
// persistence >= min_persistence (PersistentMaxima) and the saddles where
// they die (the highest maximum has none). Source and distances are kept.
// This is the persistence simplification that replaces the cycle-size
// filter of 4.3 in TopologyMethod::kPersistence (extract.h): a maximum
// survives when the protrusion it tips is at least min_persistence long,
// whatever the mesh resolution, and a saddle survives when it is where such
// a protrusion branches off. Cost O(n log n + e). Thread-safe.
CriticalPoints SimplifyByPersistence(const MeshGraph& graph,
                                     const CriticalPoints& set,
                                     double min_persistence);

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
// examined maximum (R x O(n log n + e) overall, 7.3.2). Not thread-safe
// per solver.
std::vector<TopologicalPoint> SelectTopologicalPoints(
    const MeshGraph& graph, DijkstraSolver& solver,
    const std::vector<CriticalPoints>& sets,
    TopologicalPointStats* stats = nullptr);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_TOPOLOGICAL_POINTS_H_
