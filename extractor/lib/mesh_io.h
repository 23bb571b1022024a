// Mesh intake: read OFF, OBJ, PLY (ASCII and binary) and STL from a file or a
// byte buffer, triangulate, validate and clean, and compute MeshStats.
//
// Two layers, each in its own files:
//   - one reader per format (mesh_io_readers.h; mesh_io_{off,obj,ply,stl}.cc
//     over the shared text scanner mesh_io_text.h) parses the bytes once
//     into a PolygonSoup, checking counts, tokens and indices as it reads
//     and naming the line or element at fault;
//   - the cleaning steps (mesh_clean.h) turn the soup into a Mesh: limits,
//     finiteness, ranges, fan triangulation, degenerate and duplicate
//     dropping, manifold check, orientation, compaction.
// File coordinates carry float precision (mesh_io_readers.h).
//
// What intake does to a mesh, in order (files and BuildMesh alike):
//   1. limits: more than max_vertices vertices or max_faces triangles is
//      RESOURCE_EXHAUSTED;
//   2. every coordinate finite and at most kMaxCoordinate in magnitude,
//      every polygon >= 3 indices, all in range, else INVALID_ARGUMENT
//      naming the vertex or face (and line in files);
//   3. polygons are fan-triangulated from their first corner (exact for
//      convex polygons, which is what mesh files hold in practice);
//   4. degenerate triangles (repeated vertex, or area <= 1e-12 x the square
//      of its longest edge) and duplicates (same three vertices, any order)
//      are dropped, counted in MeshStats and reported in warnings;
//   5. an edge with more than two triangles, or a vertex whose triangles form
//      more than one fan, is INVALID_ARGUMENT naming the edge / vertex;
//   6. orientation is made consistent per component (faces flipped to agree
//      with the majority; closed components end up counter-clockwise seen
//      from outside); a non-orientable component is INVALID_ARGUMENT;
//   7. unreferenced vertices are removed (ids compacted), counted, reported;
//   8. nothing left (no vertex or no triangle) is INVALID_ARGUMENT.
// Ids in messages are the input's ids (0-based; for STL, after welding).
//
//   absl::StatusOr<LoadedMesh> m =
//       LoadMeshFromFile("dog.off", IntakeOptions{});
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
#include "extractor/lib/mesh_clean.h"

namespace tpr::extract {

// MeshFormat of a file; kUnknown guesses from the name, then the bytes.
enum class MeshFormat { kUnknown, kOff, kObj, kPly, kStl };

// LoadMeshFromBuffer parses `bytes` as `format` (guessing from `file_name`
// and the bytes when kUnknown) and validates the result.
// Errors: INVALID_ARGUMENT for malformed or non-manifold input (the message
// names the format and the line, face or vertex at fault), or when the format
// cannot be guessed; RESOURCE_EXHAUSTED above the limits (a header whose
// counts the bytes cannot hold is INVALID_ARGUMENT, checked first, so a lying
// header never allocates). Binary OFF and OFF header variants (COFF, NOFF,
// ...) are INVALID_ARGUMENT. Thread-safe (no shared state). O(n log n) in the
// number of faces; memory a small multiple of the input bytes (see
// mesh_io_readers.h). Timings: bench_extract BM_ReadMesh.
absl::StatusOr<LoadedMesh> LoadMeshFromBuffer(absl::string_view bytes,
                                              MeshFormat format,
                                              absl::string_view file_name,
                                              const IntakeOptions& options);

// LoadMeshFromFile reads `path` and calls LoadMeshFromBuffer. NOT_FOUND when
// the file cannot be opened.
absl::StatusOr<LoadedMesh> LoadMeshFromFile(const std::string& path,
                                            const IntakeOptions& options);

// BuildMesh validates and cleans a polygon mesh built in code (tests, the
// synthetic generator) through exactly the steps listed at the top of this
// header. `polygons` hold vertex ids into `positions`, at least 3 each.
// Errors: INVALID_ARGUMENT (non-finite coordinate, index out of range,
// polygon with < 3 ids, non-manifold edge or vertex, non-orientable, empty),
// RESOURCE_EXHAUSTED above the limits. Thread-safe. O(n log n).
absl::StatusOr<LoadedMesh> BuildMesh(std::vector<Eigen::Vector3d> positions,
                                     std::vector<std::vector<int32_t>> polygons,
                                     const IntakeOptions& options);

// MeshFormatName returns "OFF", "OBJ", "PLY", "STL" or "unknown".
const char* MeshFormatName(MeshFormat format);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_MESH_IO_H_
