// Handles (genus > 0): find the shortest non-separating cycle of a closed
// mesh and cut the surface open along it, capping both sides, until the
// mesh has genus 0.
//
// Why. TPR is defined for genus-0 surfaces (Tam & Lau 2007, 7.4: "our
// method does not handle models of genus > 0"): a handle gives the geodesic
// wavefronts of 4.3 and 4.6 a loop, and a shortcut that moves every
// integral geodesic (4.1). Where a handle is a contact fused into the
// surface (a tail tip grown into a foot, two thighs touching: the genus-1
// meshes of SHREC'11 simplified), it also changes the Laplace-Beltrami
// spectrum (a mode of the parts that touch disappears, and every later
// eigenvalue moves up one index). Cutting a handle where it is thinnest is
// the minimal change that makes the surface genus 0 (a cup keeps its
// handle as a hook): the same treatment for every mesh, with no bound on
// what counts as a handle. docs/results.md measures it on every dev set.
//
// How. The shortest non-separating (homologically non-trivial) cycle is
// the shortest cycle of mesh edges that is not a boundary. Tree-cotree
// (Eppstein 2003) gives 2g leftover edges whose dual cycles (cocycles)
// span the cohomology: a cycle is non-trivial in Z/2 homology iff it
// crosses some cocycle an odd number of times. The shortest non-trivial
// cycle through a vertex r is two shortest paths from r plus one edge
// (Erickson and Har-Peled 2004), and a non-trivial cycle crosses some
// cocycle, so it passes through an end of a cocycle edge: sweeping from
// each such vertex, each sweep bounded by half the best cycle so far,
// finds the shortest exactly. Lengths are Euclidean edge lengths (the
// mesh graph's geodesics).
//
//   absl::StatusOr<HandleCut> cut = CutHandles(mesh, HandleCutOptions{});
//   if (cut.ok() && cut->handles_cut > 0) Describe(cut->mesh);
#ifndef TPR_EXTRACTOR_LIB_MESH_HANDLES_H_
#define TPR_EXTRACTOR_LIB_MESH_HANDLES_H_

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "extractor/lib/mesh.h"

namespace tpr::extract {

// ShortestNonSeparatingCycle returns the vertices, in order around the
// cycle, of a shortest non-separating edge cycle of `mesh` (the first
// vertex is not repeated; consecutive vertices, and the last and the
// first, share an edge), and its length in *length when non-null. Returns
// an empty vector when every cycle separates (genus 0 in every
// component). Preconditions: `mesh` as intake leaves it (manifold,
// consistently oriented, ids in range). Errors: FAILED_PRECONDITION when
// the mesh has a boundary edge (handles of a surface with boundary are not
// searched) or a genus above 32 (the Z/2 crossing masks hold 64
// cocycles). Cost: O(F log F) for the edges and the tree-cotree, plus one
// Dijkstra sweep from every end of a cocycle edge, each bounded by half
// the shortest cycle found so far. Thread-safe.
absl::StatusOr<std::vector<int32_t>> ShortestNonSeparatingCycle(
    const Mesh& mesh, double* length = nullptr);

// CutAlongCycle cuts `mesh` open along `cycle` (a simple edge cycle, as
// ShortestNonSeparatingCycle returns it) and closes both sides: every
// cycle vertex gets a copy, which the triangles on the cycle's left (the
// side of the triangles that traverse its edges in cycle order) take; each
// side is then capped by a fan of triangles to a new vertex at the
// cycle's centroid (original side first). Appends cycle.size() + 2
// vertices; copies sit at the original's position. For a non-separating
// cycle of a closed mesh the genus drops by one and the mesh stays
// connected, closed and consistently oriented. Errors: INVALID_ARGUMENT
// when the cycle has fewer than 3 vertices, repeats a vertex, or a pair of
// consecutive vertices is not a mesh edge of two triangles (the message
// names it). O(F log F). Thread-safe.
absl::Status CutAlongCycle(const std::vector<int32_t>& cycle, Mesh* mesh);

// HandleCutOptions bounds CutHandles.
struct HandleCutOptions {
  // At most this many handles are cut (each one costs a search). In
  // [0, 32]. Default 32, the largest genus ShortestNonSeparatingCycle
  // handles.
  int max_handles = 32;
};

// HandleCut is CutHandles' result.
struct HandleCut {
  // The mesh after the cuts (a copy of the input when nothing was cut).
  Mesh mesh;
  // Per vertex of `mesh`: the input vertex it comes from (a copy made by a
  // cut maps to its original, a cap's centre to the cycle's first vertex),
  // so that per-vertex results can be drawn on the input.
  std::vector<int32_t> origin;
  // Handles cut, and each cut cycle's length (mesh units), in cut order.
  int handles_cut = 0;
  std::vector<double> cycle_lengths;
};

// CutHandles cuts the shortest non-separating cycle (CutAlongCycle) again
// and again until none is left or options.max_handles were cut. Genus 0
// meshes come back unchanged at the cost of one tree-cotree. Errors: those
// of ShortestNonSeparatingCycle (a mesh with boundary, genus > 32),
// INVALID_ARGUMENT for options out of range, INTERNAL should a cut not
// lower the genus (not seen). Cost: per handle, that of
// ShortestNonSeparatingCycle. Thread-safe.
absl::StatusOr<HandleCut> CutHandles(const Mesh& mesh,
                                     const HandleCutOptions& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_MESH_HANDLES_H_
