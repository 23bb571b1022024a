// The triangle mesh every extraction stage reads: flat arrays indexed by
// vertex and face id, no hidden per-element properties.
//
//   tpr::extract::Mesh mesh;                       // usually from LoadMesh()
//   mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
//   mesh.triangles = {{0, 1, 2}};
#ifndef TPR_EXTRACTOR_LIB_MESH_H_
#define TPR_EXTRACTOR_LIB_MESH_H_

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

namespace tpr::extract {

// Mesh is an indexed triangle mesh. Intake (mesh_io.h) guarantees, for a mesh
// it returns: every coordinate finite, every index in range, no zero-area or
// duplicate triangle, every edge shared by at most two triangles with
// consistent orientation, every vertex's fan a single disk or half-disk.
struct Mesh {
  // Vertex positions, in the file's length unit.
  std::vector<Eigen::Vector3d> positions;
  // Triangles as vertex ids, counter-clockwise seen from outside.
  std::vector<std::array<int32_t, 3>> triangles;
};

// MeshStats describes a mesh as read; it travels in the signature.
struct MeshStats {
  int64_t vertices = 0;
  int64_t faces = 0;
  // Total surface area, in the square of the file's length unit.
  double area = 0.0;
  // Edges with exactly one incident face.
  int64_t boundary_edges = 0;
  // Connected components of faces.
  int64_t components = 0;
  // Sum over components of (2 - V + E - F - B) / 2, B = boundary loops.
  int64_t genus = 0;
  int64_t dropped_degenerate_faces = 0;
  int64_t dropped_duplicate_faces = 0;
  int64_t unreferenced_vertices = 0;
  // Intake's repairs (mesh_clean.h RepairNonManifold): input edges shared
  // by 3+ triangles, vertices split because their triangles formed 2+
  // fans, and edges cut open to orient a non-orientable surface.
  int64_t non_manifold_edges = 0;
  int64_t non_manifold_vertices = 0;
  int64_t orientation_cuts = 0;
};

// ComputeMeshStats returns the vertex, face, area, boundary-edge, component
// and genus figures of `mesh`; the dropped_*, unreferenced_vertices and
// repair counters are left 0 (intake fills them in).
//
// Components are connected components of faces (two faces are connected when
// they share an edge). Vertices count only when a face references them. The
// genus is summed over components c from the Euler characteristic with
// boundary: genus_c = (2 - V_c + E_c - F_c - B_c) / 2, where B_c is the
// number of boundary loops (connected pieces of the boundary-edge graph) of c.
// A closed sphere gives 0, a torus 1, a disk 0, an annulus 0.
//
// Precondition: every index in range (asserted in debug builds); the figures
// are meaningful for meshes satisfying the intake guarantees listed on Mesh.
// Cost: O(F log F) time, O(V + F) memory. Thread-safe (pure function).
MeshStats ComputeMeshStats(const Mesh& mesh);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_MESH_H_
