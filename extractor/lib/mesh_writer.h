// Mesh output: write a Mesh as OFF or PLY (ASCII or binary little-endian),
// optionally with one RGB colour per vertex (COFF / PLY red, green, blue).
// The output reloads through mesh_io.h with the same triangles and the same
// vertices (to the float precision intake keeps).
//
//   absl::StatusOr<std::string> bytes =
//       WriteMeshToString(mesh, MeshWriteOptions{MeshWriteFormat::kPlyBinary});
//   if (bytes.ok()) Save(*bytes);
#ifndef TPR_EXTRACTOR_LIB_MESH_WRITER_H_
#define TPR_EXTRACTOR_LIB_MESH_WRITER_H_

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "extractor/lib/mesh.h"

namespace tpr::extract {

// MeshWriteFormat is the file format WriteMeshToString produces.
enum class MeshWriteFormat { kOff, kPlyAscii, kPlyBinary };

// Rgb is an 8-bit colour.
using Rgb = std::array<uint8_t, 3>;

// MeshWriteOptions controls the output.
struct MeshWriteOptions {
  // Default kOff.
  MeshWriteFormat format = MeshWriteFormat::kOff;
  // Per-vertex colours: empty (no colour), or exactly one per vertex. OFF
  // then becomes COFF, which viewers read but intake does not (plain OFF
  // only): use PLY for coloured meshes that must reload. Default empty.
  std::vector<Rgb> vertex_colors;
  // Significant digits of ASCII coordinates. 17 writes the shortest text
  // that reads back as the same double; fewer make smaller files.
  // Accepted range [6, 17].
  // Default 17. Binary PLY always stores doubles exactly.
  int digits = 17;
};

// WriteMeshToString returns `mesh` encoded as options.format. The output is
// a pure function of the inputs (byte-identical for equal inputs).
// Errors: INVALID_ARGUMENT when a triangle index is out of range, a
// coordinate is not finite, vertex_colors has the wrong size, or digits is
// out of range. Thread-safe. O(V + F).
absl::StatusOr<std::string> WriteMeshToString(const Mesh& mesh,
                                              const MeshWriteOptions& options);

// WriteMeshToFile writes WriteMeshToString's bytes to `path` (replacing it).
// Errors: as WriteMeshToString; when the file cannot be written, a code
// that retrying does not change, with the path and the system's reason in
// the message (callers pass their own paths only): NOT_FOUND (a directory
// on the path is missing), PERMISSION_DENIED, RESOURCE_EXHAUSTED (disk full
// or quota), FAILED_PRECONDITION (anything else: a directory, a read-only
// file system). A failed write may leave a partial file.
// Thread-safe for distinct paths. O(V + F).
absl::Status WriteMeshToFile(const Mesh& mesh, const MeshWriteOptions& options,
                             const std::string& path);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_MESH_WRITER_H_
