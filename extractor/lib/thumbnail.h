// Thumbnails: a small deterministic software rasterizer (z-buffer, no GPU,
// no display) that draws a mesh from a fixed three-quarter view, shaded,
// with an optional TPR overlay, and encodes the picture as a PNG.
//
//   ThumbnailOverlay overlay = OverlayFromExplanation(signature, explanation);
//   absl::StatusOr<std::string> png =
//       RenderThumbnailPng(mesh, overlay, ThumbnailOptions{});
#ifndef TPR_EXTRACTOR_LIB_THUMBNAIL_H_
#define TPR_EXTRACTOR_LIB_THUMBNAIL_H_

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "extractor/lib/mesh.h"
#include "extractor/lib/signature.h"

namespace tpr::extract {

// ThumbnailOptions controls the picture.
struct ThumbnailOptions {
  // Width and height in pixels. Accepted range [16, 2048]. Default 256.
  int size = 256;
  // Empty pixels left on each side of the mesh's projected bounding box, in
  // pixels: the longer side of the box spans size - 2 * margin pixels.
  // Accepted range [0, size / 4]. Default 8.
  int margin = 8;
};

// ThumbnailOverlay is what is drawn over the shaded surface, as vertex ids
// of the mesh: points as dots, rings as lines along the mesh edges joining
// two of the ring's vertices. Both are drawn with depth, so a feature on
// the far side of the surface is hidden.
struct ThumbnailOverlay {
  // Topological points, one vertex each.
  std::vector<int32_t> points;
  // Topological rings: each the set of its wavefront's vertices (any order).
  std::vector<std::vector<int32_t>> rings;
};

// ThumbnailView is the fixed camera: an orthographic projection along
// `forward` (from the viewer into the scene), `right` to the image's right,
// `up` to its top. The three are orthonormal and right-handed
// (right x up = -forward). Seen from above-front-right: the camera turns
// 35 degrees about +y and looks 25 degrees down, so y is up, as in most
// mesh files.
struct ThumbnailView {
  Eigen::Vector3d right;
  Eigen::Vector3d up;
  Eigen::Vector3d forward;
};

// FixedThumbnailView returns the camera every thumbnail uses. O(1).
// Thread-safe.
ThumbnailView FixedThumbnailView();

// RgbaImage is a picture, rows top to bottom, 4 bytes (R, G, B, A) per
// pixel, alpha 0 where no surface is.
struct RgbaImage {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> rgba;
};

// RenderThumbnail draws `mesh` seen through FixedThumbnailView: the mesh's
// projected bounding box is centred in the image and scaled to fit inside
// the margin (orthographic, aspect kept), each triangle filled with a
// z-buffer (pixel centres, top-left fill rule on coordinates snapped to
// 1/16 pixel, so adjacent triangles neither overlap nor leave gaps) and
// shaded flat with Lambert's law under a fixed light from the viewer's
// upper left (the side facing the viewer is lit, for open meshes); then
// `overlay` on top. Surface pixels are opaque, the rest transparent.
// Deterministic: the same inputs give the same pixels, on every run and
// thread (no threads, no uninitialised state; compiled without
// floating-point contraction).
// Errors: INVALID_ARGUMENT when options are out of range, the mesh has no
// triangle, an index or overlay vertex is out of range, a coordinate is not
// finite, or the projected mesh has no extent (the message says which).
// Cost: O(V + F + pixels covered); about 2 ms at 20k triangles (see
// docs/benchmarks.md). Thread-safe (pure function).
absl::StatusOr<RgbaImage> RenderThumbnail(const Mesh& mesh,
                                          const ThumbnailOverlay& overlay,
                                          const ThumbnailOptions& options);

// EncodePng returns `image` as an 8-bit RGBA PNG (zlib level 6, no
// interlace, no time or text chunks): the same image gives the same bytes.
// Errors: INVALID_ARGUMENT when the buffer does not match the size;
// INTERNAL when libpng fails. O(pixels). Thread-safe.
absl::StatusOr<std::string> EncodePng(const RgbaImage& image);

// RenderThumbnailPng is EncodePng(RenderThumbnail(...)); same errors.
absl::StatusOr<std::string> RenderThumbnailPng(const Mesh& mesh,
                                               const ThumbnailOverlay& overlay,
                                               const ThumbnailOptions& options);

// OverlayFromExplanation returns the overlay of one extraction: each point
// feature's vertex and each ring feature's vertices (Explanation::
// feature_vertices, parallel to Signature::features). Features whose
// vertex list is empty are left out. O(total vertices). Thread-safe.
ThumbnailOverlay OverlayFromExplanation(const Signature& signature,
                                        const Explanation& explanation);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_THUMBNAIL_H_
