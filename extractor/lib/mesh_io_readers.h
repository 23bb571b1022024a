// One reader per mesh format, each a pure function from a file's bytes to a
// PolygonSoup (mesh_clean.h), which CleanPolygonSoup turns into a Mesh.
// LoadMeshFromBuffer (mesh_io.h) picks the reader; fuzz targets and tests
// may call one directly. To add a format: write mesh_io_<format>.cc with a
// Read<Format> declared here, add a MeshFormat value (mesh_io.h) and a row
// to kReaders in mesh_io.cc.
//
// Every reader parses the bytes exactly once and checks what it reads as it
// goes: declared counts against the bytes left (a lying header never
// allocates), counts against IntakeOptions before storing anything (a
// polygon's corners are counted before they are stored, so a face over the
// limit is refused holding nothing), every token and index, naming the
// format and the line or element at fault. Memory: the soup holds 24 bytes
// per vertex and 4 per corner (plus 8 per polygon), each of which takes
// several input bytes; reading and cleaning together peak at 7-9 times the
// input for the tersest valid OBJ, and tests/extractor/mesh_memory_test.cc
// holds intake to at most 12 times its input plus 1 MiB.
// Coordinates are rounded to float precision (what the readers have always
// kept; see ParseCoordinate in mesh_io_text.h).
//
//   absl::StatusOr<PolygonSoup> soup = ReadOff(bytes, IntakeOptions{});
#ifndef TPR_EXTRACTOR_LIB_MESH_IO_READERS_H_
#define TPR_EXTRACTOR_LIB_MESH_IO_READERS_H_

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "extractor/lib/mesh_clean.h"

namespace tpr::extract {

// ReadOff reads plain ASCII OFF ("OFF", counts, vertices, faces; '#'
// comments). Errors: INVALID_ARGUMENT naming the line (binary OFF and the
// COFF/NOFF/... variants included); RESOURCE_EXHAUSTED above the limits.
// O(bytes). Thread-safe.
absl::StatusOr<PolygonSoup> ReadOff(absl::string_view bytes,
                                    const IntakeOptions& options);

// ReadObj reads the "v" and "f" statements of Wavefront OBJ (1-based and
// negative indices, "i/t/n" references); every other statement is ignored.
// A face's repeated indices are removed (first occurrence kept), and a face
// left with fewer than 3 is counted in reader_dropped_degenerate. Errors:
// INVALID_ARGUMENT naming the line; RESOURCE_EXHAUSTED above the limits.
// O(bytes). Thread-safe.
absl::StatusOr<PolygonSoup> ReadObj(absl::string_view bytes,
                                    const IntakeOptions& options);

// ReadPly reads PLY 1.0, ASCII and binary in either byte order: vertex
// x, y, z and face vertex_indices (or vertex_index) as the face's first
// property; other elements and properties are skipped. Errors:
// INVALID_ARGUMENT naming the header line or element; RESOURCE_EXHAUSTED
// above the limits. O(bytes). Thread-safe.
absl::StatusOr<PolygonSoup> ReadPly(absl::string_view bytes,
                                    const IntakeOptions& options);

// ReadStl reads ASCII or binary STL (binary when the 80-byte header's count
// matches the size exactly, or the text does not start with "solid").
// Corners at equal float positions (+0 = -0, subnormals = 0) are welded into
// one vertex, numbered in order of first appearance; a facet whose corners weld
// together is counted in reader_dropped_degenerate; a warning says how many
// corners became how many vertices. Errors: INVALID_ARGUMENT naming the line
// or triangle; RESOURCE_EXHAUSTED above the limits. O(bytes). Thread-safe.
absl::StatusOr<PolygonSoup> ReadStl(absl::string_view bytes,
                                    const IntakeOptions& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_MESH_IO_READERS_H_
