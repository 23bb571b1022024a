// The triangle mesh every extraction stage reads: flat arrays indexed by
// vertex and face id, no hidden per-element properties.
//
//   tpr::extract::Mesh mesh;                       // usually from LoadMesh()
//   mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
//   mesh.triangles = {{0, 1, 2}};
#ifndef TPR_EXTRACTOR_LIB_MESH_H_
#define TPR_EXTRACTOR_LIB_MESH_H_

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

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
};

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_MESH_H_
