// Mesh cleaning: the steps that turn a polygon soup (what a file reader or a
// caller produces) into the Mesh every extraction stage reads. Each step is a
// named function, tested on its own (tests/extractor/mesh_clean_test.cc);
// CleanPolygonSoup runs them in the order listed below, and is what
// LoadMeshFromBuffer and BuildMesh (mesh_io.h) call.
//
//   1. ValidatePolygonSoup: limits, finite coordinates, polygon sizes, index
//      ranges;
//   2. FanTriangulate: each polygon from its first corner;
//   3. DropDegenerateTriangles: repeated vertex, or zero area up to rounding;
//   4. DropDuplicateTriangles: same three vertices in any order;
//   5. RepairNonManifold: an edge of 3+ triangles is cut, a non-orientable
//      surface is cut open where its orientation conflicts, and a vertex
//      whose triangles form 2+ fans is split into one vertex per fan, so
//      the result is manifold sheets; orientation as OrientConsistently;
//   6. DropDebris (debris.h): components under 1% of the largest one's area
//      and vertex count removed;
//   7. CompactVertices: unreferenced vertices removed, ids compacted.
// CheckManifold and OrientConsistently are the strict forms of step 5 (an
// error instead of a repair), for callers that must not change topology.
//
//   PolygonSoup soup;
//   soup.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
//   soup.AddPolygon({0, 1, 2});
//   absl::StatusOr<LoadedMesh> m = CleanPolygonSoup(std::move(soup), {});
#ifndef TPR_EXTRACTOR_LIB_MESH_CLEAN_H_
#define TPR_EXTRACTOR_LIB_MESH_CLEAN_H_

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "extractor/lib/intake.h"
#include "extractor/lib/mesh.h"

namespace tpr::extract {

// PolygonSoup is vertices plus polygons as flat corner lists, the form every
// reader produces (one allocation per array, not per polygon).
struct PolygonSoup {
  std::vector<Eigen::Vector3d> positions;
  // Polygon p's vertex ids are corners[offsets[p] .. offsets[p + 1]).
  std::vector<int32_t> corners;
  std::vector<int64_t> offsets{0};
  // Faces a reader dropped before cleaning because their corners coincide
  // (STL welding, OBJ repeated indices); counted as degenerate.
  int64_t reader_dropped_degenerate = 0;
  // Reader notes (STL welding), passed on to LoadedMesh::warnings.
  std::vector<std::string> warnings;

  int64_t num_polygons() const {
    return static_cast<int64_t>(offsets.size()) - 1;
  }
  absl::Span<const int32_t> polygon(int64_t p) const {
    return absl::MakeConstSpan(corners.data() + offsets[p],
                               offsets[p + 1] - offsets[p]);
  }
  void AddPolygon(absl::Span<const int32_t> ids) {
    corners.insert(corners.end(), ids.begin(), ids.end());
    offsets.push_back(static_cast<int64_t>(corners.size()));
  }
  void AddPolygon(std::initializer_list<int32_t> ids) {
    AddPolygon(absl::MakeConstSpan(ids.begin(), ids.size()));
  }
};

using Triangles = std::vector<std::array<int32_t, 3>>;

// ValidatePolygonSoup checks `soup` before any cleaning.
// Errors: RESOURCE_EXHAUSTED when positions exceed options.max_vertices or
// the fan triangulation would exceed options.max_faces (both messages name
// the option); INVALID_ARGUMENT for no vertex, no polygon, a non-finite
// coordinate ("vertex V has a non-finite coordinate"), a coordinate beyond
// kMaxCoordinate ("vertex V: coordinate X exceeds the supported magnitude
// 1e15"), a polygon with fewer
// than 3 ids ("face F has N vertices") or an id out of range ("face F
// references vertex V"). Ids are the soup's. O(V + corners). Thread-safe.
absl::Status ValidatePolygonSoup(const PolygonSoup& soup,
                                 const IntakeOptions& options);

// FanTriangulate returns each polygon split into a fan from its first
// corner, in polygon order: (c0, c1, c2), (c0, c2, c3), ... Exact for convex
// polygons (what mesh files hold in practice). Precondition: soup validated.
// O(corners). Thread-safe.
Triangles FanTriangulate(const PolygonSoup& soup);

// DropDegenerateTriangles removes triangles with a repeated vertex id or a
// doubled area at most 1e-12 times their longest squared edge (scale-free:
// collinear up to rounding), keeping the order of the rest, and returns how
// many it removed. O(F). Thread-safe.
int64_t DropDegenerateTriangles(const std::vector<Eigen::Vector3d>& positions,
                                Triangles* triangles);

// DropDuplicateTriangles removes every triangle whose vertex set equals an
// earlier triangle's (any order, either orientation), keeping the first, and
// returns how many it removed. O(F log F). Thread-safe.
int64_t DropDuplicateTriangles(Triangles* triangles);

// CheckManifold returns OK when every edge has at most two triangles and
// every vertex's triangles form one fan (a disk or half-disk), else
// INVALID_ARGUMENT naming the smallest offending edge ("non-manifold edge
// (a, b): shared by N triangles") or vertex ("non-manifold vertex v: its
// triangles form N separate fans"); edges are checked first.
// Precondition: ids in [0, num_vertices). O(F log F). Thread-safe.
absl::Status CheckManifold(int64_t num_vertices, const Triangles& triangles);

// OrientConsistently flips triangles so that neighbours across every edge
// traverse it in opposite directions: per connected component the majority
// orientation is kept, except that a closed component is turned to a
// positive signed volume (counter-clockwise seen from outside). Returns the
// number of triangles flipped. Errors: INVALID_ARGUMENT "non-orientable
// surface: triangles around edge (a, b) cannot be oriented consistently".
// Edges of 3+ triangles join nothing. O(F log F). Thread-safe.
absl::StatusOr<int64_t> OrientConsistently(
    const std::vector<Eigen::Vector3d>& positions, Triangles* triangles);

// ManifoldRepair counts what RepairNonManifold changed.
struct ManifoldRepair {
  // Edges of the input shared by 3 or more triangles.
  int64_t non_manifold_edges = 0;
  // Vertices split because their triangles formed 2 or more fans (pinch
  // vertices, and the ends of cut edges whose sides fall apart).
  int64_t split_vertices = 0;
  // Copies of vertices appended to the positions (fans after the first,
  // and detached triangles' corners).
  int64_t added_vertices = 0;
  // Edges of two triangles cut open because the surface is not orientable
  // (a Moebius strip needs one).
  int64_t orientation_cuts = 0;
  // Triangles given their own three vertices because a cut edge would
  // otherwise close again (not seen outside constructed cases).
  int64_t detached_triangles = 0;
  // Triangles flipped for a consistent orientation.
  int64_t reoriented = 0;
};

// RepairNonManifold makes `triangles` an oriented 2-manifold with boundary,
// changing connectivity only where it is not one, and never dropping a
// triangle:
//   - an edge of 3 or more triangles joins none of them: each has it as a
//     border (the sheets meeting there fall apart along it, then rejoin
//     wherever their vertices' fans still connect them);
//   - orientation as OrientConsistently, except that a link contradicting
//     the orientation already given is cut instead of refused;
//   - each vertex gets one id per fan of its triangles (joined across the
//     edges kept above); the fan of its first corner keeps the id, others
//     get copies appended to *positions;
//   - should a cut edge rejoin because both its ends stayed single fans,
//     the faces along it but the first are detached (own vertex copies)
//     and the steps run again.
// The sheets meeting at a non-manifold edge are not paired by angle: the
// edge is cut, so two closed surfaces sharing an edge stay two closed
// surfaces, and a fin comes off the surface it stands on. Returns the
// counts. Precondition: ids in range, no degenerate or duplicate triangle.
// Positions of copies equal the original's. O(F log F). Thread-safe.
ManifoldRepair RepairNonManifold(std::vector<Eigen::Vector3d>* positions,
                                 Triangles* triangles);

// VertexOrder is how CompactVertices numbers the vertices it keeps.
enum class VertexOrder {
  // In their original order (intake: a file's vertex ids stay recognizable).
  kOriginal,
  // In the order triangles first reference them (the spectrum's matrices
  // and the decimater's input are numbered so).
  kFirstReference,
};

// CompactVertices removes the vertices no triangle references, renumbers
// the rest in `order`, and returns how many it removed. O(V + F).
// Thread-safe.
int64_t CompactVertices(std::vector<Eigen::Vector3d>* positions,
                        Triangles* triangles,
                        VertexOrder order = VertexOrder::kOriginal);

// CleanPolygonSoup runs the steps at the top of this header and returns the
// mesh, its ComputeMeshStats figures with the dropped/unreferenced counters
// filled in, and one warning per step that changed something (after the
// soup's own warnings; a repair names its counts). Errors: those of
// ValidatePolygonSoup; INVALID_ARGUMENT "mesh has no faces left after
// dropping ..." when cleaning leaves nothing. O(F log F). Thread-safe.
absl::StatusOr<LoadedMesh> CleanPolygonSoup(PolygonSoup soup,
                                            const IntakeOptions& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_MESH_CLEAN_H_
