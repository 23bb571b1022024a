// Previews: a mesh simplified for 3D views (quadric error edge collapses)
// and written as a compact binary PLY.
//
//   absl::StatusOr<std::string> ply = MakePreviewPly(mesh, PreviewOptions{});
//   if (ply.ok()) Send(*ply);   // <= 5,000 triangles, float coordinates
#ifndef TPR_EXTRACTOR_LIB_PREVIEW_H_
#define TPR_EXTRACTOR_LIB_PREVIEW_H_

#include <string>

#include "absl/status/statusor.h"
#include "extractor/lib/mesh.h"

namespace tpr::extract {

// PreviewOptions controls the simplification.
struct PreviewOptions {
  // Most triangles the preview may have. Accepted range [4, 10,000,000].
  // Default 5,000: a few hundred kilobytes at most, smooth enough to turn
  // in a browser.
  int max_faces = 5000;
};

// SimplifyForPreview returns `mesh` with at most options.max_faces
// triangles: unchanged (but for unreferenced vertices, removed) when it has
// no more; otherwise decimated by halfedge collapses in the order of
// Garland and Heckbert's quadric error (area-weighted plane quadrics, as
// OpenMesh's ModQuadricT; every vertex kept stays where it was, so the
// preview shares the mesh's coordinates) until the count is reached.
// Collapses that would break the link condition, pinch a boundary, flip or
// flatten a triangle or duplicate one are refused, so the topology is
// kept; when the refusals leave it above the limit (many tiny closed
// components) the result is FAILED_PRECONDITION. Ties are broken by vertex
// ids: the same mesh gives the same preview. Precondition: a mesh as
// intake returns it (manifold, oriented). Errors: INVALID_ARGUMENT for
// max_faces out of range or an index out of range; FAILED_PRECONDITION as
// above. Cost: O(F log F), about 10 ms at 20k triangles (docs/
// benchmarks.md, BM_Preview). Thread-safe (pure function).
absl::StatusOr<Mesh> SimplifyForPreview(const Mesh& mesh,
                                        const PreviewOptions& options);

// EncodePreviewPly returns `mesh` as a binary little-endian PLY: `element
// vertex` with float x, y, z (the mesh's doubles rounded to float), then
// `element face` with `list uchar int vertex_indices`, 3 per face. The
// same mesh gives the same bytes. Precondition: indices in range
// (asserted). O(V + F). Thread-safe.
std::string EncodePreviewPly(const Mesh& mesh);

// MakePreviewPly is EncodePreviewPly(SimplifyForPreview(...)); same errors.
// Deterministic.
absl::StatusOr<std::string> MakePreviewPly(const Mesh& mesh,
                                           const PreviewOptions& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_PREVIEW_H_
