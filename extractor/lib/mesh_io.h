// Mesh intake: read OFF, OBJ, PLY (ASCII and binary) and STL from a file or a
// byte buffer, triangulate, validate, and compute MeshStats.
//
//   absl::StatusOr<LoadedMesh> m = LoadMeshFromFile("dog.off", IntakeOptions{});
//   if (!m.ok()) return m.status();   // INVALID_ARGUMENT names the fault
//   Use(m->mesh, m->stats);
#ifndef TPR_EXTRACTOR_LIB_MESH_IO_H_
#define TPR_EXTRACTOR_LIB_MESH_IO_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "extractor/lib/mesh.h"

namespace tpr::extract {

// MeshFormat of a file; kUnknown guesses from the name, then the bytes.
enum class MeshFormat { kUnknown, kOff, kObj, kPly, kStl };

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

// LoadMeshFromBuffer parses `bytes` as `format` (guessing from `file_name`
// and the bytes when kUnknown) and validates the result.
// Errors: INVALID_ARGUMENT for malformed or non-manifold input (the message
// names the line, face or vertex at fault), RESOURCE_EXHAUSTED above the
// limits. Thread-safe. O(n log n) in the number of faces.
absl::StatusOr<LoadedMesh> LoadMeshFromBuffer(absl::string_view bytes,
                                              MeshFormat format,
                                              absl::string_view file_name,
                                              const IntakeOptions& options);

// LoadMeshFromFile reads `path` and calls LoadMeshFromBuffer. NOT_FOUND when
// the file cannot be opened.
absl::StatusOr<LoadedMesh> LoadMeshFromFile(const std::string& path,
                                            const IntakeOptions& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_MESH_IO_H_
