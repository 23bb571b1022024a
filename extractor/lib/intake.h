// Intake's bounds and result: what LoadMeshFromBuffer, BuildMesh
// (mesh_io.h) and CleanPolygonSoup (mesh_clean.h) accept and return, in a
// header of its own so that the readers' text scanner (mesh_io_text.h) and
// the cleaning steps share it without including each other.
//
//   IntakeOptions options;
//   options.max_vertices = 100'000;  // RESOURCE_EXHAUSTED beyond it
//   absl::StatusOr<LoadedMesh> m = LoadMeshFromBuffer(bytes, format, name,
//                                                     options);
#ifndef TPR_EXTRACTOR_LIB_INTAKE_H_
#define TPR_EXTRACTOR_LIB_INTAKE_H_

#include <cstdint>
#include <string>
#include <vector>

#include "extractor/lib/mesh.h"

namespace tpr::extract {

// kMaxCoordinate bounds every coordinate's magnitude, in files and
// BuildMesh alike. Beyond it, squared lengths, areas and the products of
// four lengths that curvature and cotangent weights form lose their meaning
// long before a double overflows (a float-range 3e38 squared twice is
// 8e153); 1e15 keeps a mesh in metres well past the solar system.
inline constexpr double kMaxCoordinate = 1e15;

// IntakeOptions bounds what intake accepts.
struct IntakeOptions {
  // Meshes with more vertices are RESOURCE_EXHAUSTED. Default 2,000,000.
  int64_t max_vertices = 2'000'000;
  // Meshes with more faces (after triangulation) are RESOURCE_EXHAUSTED.
  // Default 4,000,000.
  int64_t max_faces = 4'000'000;
};

// LoadedMesh is a validated mesh with its statistics.
struct LoadedMesh {
  Mesh mesh;
  MeshStats stats;
  // Dropped faces and similar, one sentence each.
  std::vector<std::string> warnings;
};

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_INTAKE_H_
