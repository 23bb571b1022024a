// The rasterizer works on coordinates snapped to 1/16 pixel with integer
// edge functions, so coverage is exact and the same on every machine; depth
// and shading are doubles computed in a fixed order from those integers.
// CMake compiles this file with -ffp-contract=off: a fused multiply-add
// would round differently from the separate operations, and golden images
// compare bytes.
#include "extractor/lib/thumbnail.h"

#include <png.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <csetjmp>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"

namespace tpr::extract {
namespace {

constexpr int kSubpixelBits = 4;
constexpr int64_t kSubpixel = int64_t{1} << kSubpixelBits;  // 16 per pixel

// Surface colour before shading, and the overlay's colours (the same as
// `tpr inspect`: points red, rings near-black).
constexpr std::array<double, 3> kSurface = {178.0, 190.0, 210.0};
constexpr std::array<uint8_t, 3> kPointColour = {220, 30, 30};
constexpr std::array<uint8_t, 3> kRingColour = {25, 25, 25};
// Lambert: ambient + diffuse * max(0, n . l).
constexpr double kAmbient = 0.22;
constexpr double kDiffuse = 0.78;
// An overlay pixel is drawn when its depth is at most the surface's there
// plus this fraction of the mesh's depth range: enough to sit on the
// surface it belongs to, too little to show through to the other side.
constexpr double kOverlayDepthSlack = 0.02;

// The projected mesh: per vertex its snapped screen position and depth.
struct Projected {
  std::vector<int64_t> x, y;  // 1/16 pixel, y down
  std::vector<double> depth;  // along forward, in mesh units
  double depth_range = 0.0;
};

double Dot(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return a.x() * b.x() + a.y() * b.y() + a.z() * b.z();
}

Eigen::Vector3d Normalized(const Eigen::Vector3d& v) {
  const double n = std::sqrt(Dot(v, v));
  return n > 0.0 ? Eigen::Vector3d(v.x() / n, v.y() / n, v.z() / n)
                 : Eigen::Vector3d(0.0, 0.0, 0.0);
}

absl::Status Validate(const Mesh& mesh, const ThumbnailOverlay& overlay,
                      const ThumbnailOptions& options) {
  if (options.size < 16 || options.size > 2048) {
    return absl::InvalidArgumentError(absl::StrCat(
        "thumbnail size must be in [16, 2048], got ", options.size));
  }
  if (options.margin < 0 || options.margin > options.size / 4) {
    return absl::InvalidArgumentError(
        absl::StrCat("thumbnail margin must be in [0, ", options.size / 4,
                     "], got ", options.margin));
  }
  if (mesh.triangles.empty()) {
    return absl::InvalidArgumentError("thumbnail: the mesh has no triangle");
  }
  const int64_t n = static_cast<int64_t>(mesh.positions.size());
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    if (!mesh.positions[v].allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("thumbnail: vertex ", v, " is not finite"));
    }
  }
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (int32_t v : mesh.triangles[f]) {
      if (v < 0 || v >= n) {
        return absl::InvalidArgumentError(absl::StrCat(
            "thumbnail: triangle ", f, " has vertex ", v, " out of range"));
      }
    }
  }
  auto check = [n](int32_t v, const char* what) -> absl::Status {
    if (v < 0 || v >= n) {
      return absl::InvalidArgumentError(absl::StrCat(
          "thumbnail overlay: ", what, " vertex ", v, " out of range"));
    }
    return absl::OkStatus();
  };
  for (int32_t v : overlay.points) {
    if (absl::Status s = check(v, "point"); !s.ok()) return s;
  }
  for (const std::vector<int32_t>& ring : overlay.rings) {
    for (int32_t v : ring) {
      if (absl::Status s = check(v, "ring"); !s.ok()) return s;
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<Projected> Project(const Mesh& mesh,
                                  const ThumbnailOptions& options) {
  const ThumbnailView view = FixedThumbnailView();
  const size_t n = mesh.positions.size();
  std::vector<double> sx(n), sy(n);
  Projected p;
  p.depth.resize(n);
  double min_x = std::numeric_limits<double>::infinity(), max_x = -min_x;
  double min_y = min_x, max_y = -min_x, min_z = min_x, max_z = -min_x;
  for (size_t v = 0; v < n; ++v) {
    const Eigen::Vector3d& q = mesh.positions[v];
    sx[v] = Dot(q, view.right);
    sy[v] = Dot(q, view.up);
    p.depth[v] = Dot(q, view.forward);
    min_x = std::min(min_x, sx[v]);
    max_x = std::max(max_x, sx[v]);
    min_y = std::min(min_y, sy[v]);
    max_y = std::max(max_y, sy[v]);
    min_z = std::min(min_z, p.depth[v]);
    max_z = std::max(max_z, p.depth[v]);
  }
  const double extent = std::max(max_x - min_x, max_y - min_y);
  if (!(extent > 0.0) || !std::isfinite(extent)) {
    return absl::InvalidArgumentError(
        "thumbnail: the mesh projects to a single point");
  }
  p.depth_range = max_z - min_z;
  const double half = options.size / 2.0;
  const double scale = (options.size - 2.0 * options.margin) / extent;
  const double cx = (min_x + max_x) / 2.0, cy = (min_y + max_y) / 2.0;
  p.x.resize(n);
  p.y.resize(n);
  for (size_t v = 0; v < n; ++v) {
    const double px = half + (sx[v] - cx) * scale;
    const double py = half - (sy[v] - cy) * scale;
    p.x[v] = std::llround(px * static_cast<double>(kSubpixel));
    p.y[v] = std::llround(py * static_cast<double>(kSubpixel));
  }
  return p;
}

class Raster {
 public:
  explicit Raster(int size)
      : size_(size),
        depth_(static_cast<size_t>(size) * size,
               std::numeric_limits<double>::infinity()),
        rgba_(static_cast<size_t>(size) * size * 4, 0) {}

  // Fills one triangle (corners in 1/16 pixel), depth-tested, in `colour`.
  void Triangle(std::array<int64_t, 3> x, std::array<int64_t, 3> y,
                std::array<double, 3> z, const std::array<uint8_t, 3>& colour);
  // Draws an overlay pixel at (px, py) if it is not behind the surface by
  // more than `slack`.
  void Plot(int px, int py, double z, double slack,
            const std::array<uint8_t, 3>& colour);

  int size() const { return size_; }
  std::vector<uint8_t> TakePixels() { return std::move(rgba_); }

 private:
  const int size_;
  std::vector<double> depth_;
  std::vector<uint8_t> rgba_;
};

void Raster::Triangle(std::array<int64_t, 3> x, std::array<int64_t, 3> y,
                      std::array<double, 3> z,
                      const std::array<uint8_t, 3>& colour) {
  int64_t area = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]);
  if (area == 0) return;
  if (area < 0) {  // either winding: both sides are drawn
    std::swap(x[1], x[2]);
    std::swap(y[1], y[2]);
    std::swap(z[1], z[2]);
    area = -area;
  }
  const int64_t limit = static_cast<int64_t>(size_) - 1;
  const int64_t x0 = std::max<int64_t>(
      0, (*std::min_element(x.begin(), x.end()) - kSubpixel / 2) / kSubpixel);
  const int64_t x1 = std::min<int64_t>(
      limit, (*std::max_element(x.begin(), x.end())) / kSubpixel);
  const int64_t y0 = std::max<int64_t>(
      0, (*std::min_element(y.begin(), y.end()) - kSubpixel / 2) / kSubpixel);
  const int64_t y1 = std::min<int64_t>(
      limit, (*std::max_element(y.begin(), y.end())) / kSubpixel);
  // Edge i runs from corner i+1 to corner i+2; its function is corner i's
  // barycentric weight times `area`. Top-left rule: a pixel centre on an
  // edge belongs to the triangle when the edge is a top or a left one.
  std::array<int64_t, 3> bias;
  for (int i = 0; i < 3; ++i) {
    const int a = (i + 1) % 3, b = (i + 2) % 3;
    const int64_t dx = x[b] - x[a], dy = y[b] - y[a];
    bias[i] = (dy < 0 || (dy == 0 && dx > 0)) ? 0 : 1;
  }
  const double inv_area = 1.0 / static_cast<double>(area);
  for (int64_t py = y0; py <= y1; ++py) {
    const int64_t cy = py * kSubpixel + kSubpixel / 2;
    for (int64_t px = x0; px <= x1; ++px) {
      const int64_t cx = px * kSubpixel + kSubpixel / 2;
      std::array<int64_t, 3> w;
      bool inside = true;
      for (int i = 0; i < 3 && inside; ++i) {
        const int a = (i + 1) % 3, b = (i + 2) % 3;
        w[i] = (x[b] - x[a]) * (cy - y[a]) - (y[b] - y[a]) * (cx - x[a]);
        inside = w[i] - bias[i] >= 0;
      }
      if (!inside) continue;
      const double b0 = static_cast<double>(w[0]) * inv_area;
      const double b1 = static_cast<double>(w[1]) * inv_area;
      const double b2 = static_cast<double>(w[2]) * inv_area;
      const double depth = b0 * z[0] + b1 * z[1] + b2 * z[2];
      const size_t at = static_cast<size_t>(py) * size_ + px;
      if (!(depth < depth_[at])) continue;
      depth_[at] = depth;
      for (int c = 0; c < 3; ++c) rgba_[at * 4 + c] = colour[c];
      rgba_[at * 4 + 3] = 255;
    }
  }
}

void Raster::Plot(int px, int py, double z, double slack,
                  const std::array<uint8_t, 3>& colour) {
  if (px < 0 || py < 0 || px >= size_ || py >= size_) return;
  const size_t at = static_cast<size_t>(py) * size_ + px;
  if (z > depth_[at] + slack) return;
  for (int c = 0; c < 3; ++c) rgba_[at * 4 + c] = colour[c];
  rgba_[at * 4 + 3] = 255;
}

// Flat Lambert shading, one colour per triangle from its normal: honest on
// flat-faced meshes (a cube's faces stay flat) and, at thumbnail size,
// smooth enough on fine ones.
std::array<uint8_t, 3> Shade(const Eigen::Vector3d& normal,
                             const Eigen::Vector3d& light,
                             const Eigen::Vector3d& forward) {
  // The side facing the viewer is lit: seen from inside (an open mesh, or
  // a face turned away at the silhouette) the surface is shaded as if
  // seen from outside.
  const double facing = Dot(normal, forward) > 0.0 ? -1.0 : 1.0;
  const double lambert = std::max(0.0, facing * Dot(normal, light));
  const double intensity = kAmbient + kDiffuse * lambert;
  std::array<uint8_t, 3> colour;
  for (int c = 0; c < 3; ++c) {
    const double value = std::clamp(kSurface[c] * intensity, 0.0, 255.0);
    colour[c] = static_cast<uint8_t>(std::lround(value));
  }
  return colour;
}

void DrawSurface(const Mesh& mesh, const Projected& p, Raster* raster) {
  const ThumbnailView view = FixedThumbnailView();
  // The light comes from behind the viewer's left shoulder, so that every
  // face turned towards the viewer gets some of it.
  const Eigen::Vector3d light =
      Normalized(-0.30 * view.right + 0.50 * view.up - 1.00 * view.forward);
  for (const auto& t : mesh.triangles) {
    const std::array<int64_t, 3> x = {p.x[t[0]], p.x[t[1]], p.x[t[2]]};
    const std::array<int64_t, 3> y = {p.y[t[0]], p.y[t[1]], p.y[t[2]]};
    const std::array<double, 3> z = {p.depth[t[0]], p.depth[t[1]],
                                     p.depth[t[2]]};
    const Eigen::Vector3d& a = mesh.positions[t[0]];
    const Eigen::Vector3d e1 = mesh.positions[t[1]] - a;
    const Eigen::Vector3d e2 = mesh.positions[t[2]] - a;
    const Eigen::Vector3d normal = Normalized(Eigen::Vector3d(
        e1.y() * e2.z() - e1.z() * e2.y(), e1.z() * e2.x() - e1.x() * e2.z(),
        e1.x() * e2.y() - e1.y() * e2.x()));
    raster->Triangle(x, y, z, Shade(normal, light, view.forward));
  }
}

double ToPixel(int64_t subpixels) {
  return static_cast<double>(subpixels) / static_cast<double>(kSubpixel);
}

// A ring is drawn along the mesh edges whose two ends are both ring
// vertices: the wavefront is a band of vertices, not an ordered polyline.
void DrawRing(const Mesh& mesh, const Projected& p,
              const std::vector<int32_t>& ring, double slack, Raster* raster) {
  std::vector<bool> on(mesh.positions.size(), false);
  for (int32_t v : ring) on[v] = true;
  std::vector<std::pair<int32_t, int32_t>> edges;
  for (const auto& t : mesh.triangles) {
    for (int i = 0; i < 3; ++i) {
      const int32_t a = t[i], b = t[(i + 1) % 3];
      if (on[a] && on[b]) edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  for (const auto& [a, b] : edges) {
    const double ax = ToPixel(p.x[a]), ay = ToPixel(p.y[a]);
    const double bx = ToPixel(p.x[b]), by = ToPixel(p.y[b]);
    const double length = std::max(std::abs(bx - ax), std::abs(by - ay));
    const int steps = std::max(1, static_cast<int>(std::ceil(length * 2.0)));
    for (int s = 0; s <= steps; ++s) {
      const double f = static_cast<double>(s) / steps;
      const double x = ax + (bx - ax) * f, y = ay + (by - ay) * f;
      const double z = p.depth[a] + (p.depth[b] - p.depth[a]) * f;
      // A 2 x 2 pixel pen centred on the line.
      const int px = static_cast<int>(std::floor(x - 0.5));
      const int py = static_cast<int>(std::floor(y - 0.5));
      for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) {
          raster->Plot(px + dx, py + dy, z, slack, kRingColour);
        }
      }
    }
  }
}

void DrawPoint(const Projected& p, int32_t v, double slack, Raster* raster) {
  const double radius = std::max(2.0, raster->size() / 64.0);
  const double cx = ToPixel(p.x[v]), cy = ToPixel(p.y[v]);
  const int r = static_cast<int>(std::ceil(radius));
  const int px = static_cast<int>(std::floor(cx));
  const int py = static_cast<int>(std::floor(cy));
  for (int y = py - r; y <= py + r; ++y) {
    for (int x = px - r; x <= px + r; ++x) {
      const double dx = x + 0.5 - cx, dy = y + 0.5 - cy;
      if (dx * dx + dy * dy > radius * radius) continue;
      raster->Plot(x, y, p.depth[v], slack, kPointColour);
    }
  }
}

void WriteToString(png_structp png, png_bytep data, png_size_t length) {
  auto* out = static_cast<std::string*>(png_get_io_ptr(png));
  out->append(reinterpret_cast<const char*>(data), length);
}

void NoFlush(png_structp) {}

// libpng reports errors by longjmp; this function holds no object with a
// destructor between setjmp and the calls that may jump.
bool EncodePngRaw(const RgbaImage& image, png_bytep* rows, std::string* out) {
  png_structp png =
      png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  if (png == nullptr) return false;
  png_infop info = png_create_info_struct(png);
  if (info == nullptr) {
    png_destroy_write_struct(&png, nullptr);
    return false;
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return false;
  }
  png_set_write_fn(png, out, WriteToString, NoFlush);
  png_set_compression_level(png, 6);
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.width),
               static_cast<png_uint_32>(image.height), 8,
               PNG_COLOR_TYPE_RGB_ALPHA, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_write_image(png, rows);
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return true;
}

}  // namespace

ThumbnailView FixedThumbnailView() {
  // cos and sin of 35 and 25 degrees, written out so that the view does
  // not depend on the C library's trigonometry.
  constexpr double kCosAz = 0.8191520442889918, kSinAz = 0.5735764363510461;
  constexpr double kCosEl = 0.9063077870366499, kSinEl = 0.42261826174069944;
  ThumbnailView view;
  // The camera sits at (sin az cos el, sin el, cos az cos el) from the
  // centre and looks back at it.
  view.forward = Eigen::Vector3d(-kSinAz * kCosEl, -kSinEl, -kCosAz * kCosEl);
  view.right = Eigen::Vector3d(kCosAz, 0.0, -kSinAz);
  view.up = Eigen::Vector3d(-kSinAz * kSinEl, kCosEl, -kCosAz * kSinEl);
  return view;
}

absl::StatusOr<RgbaImage> RenderThumbnail(const Mesh& mesh,
                                          const ThumbnailOverlay& overlay,
                                          const ThumbnailOptions& options) {
  if (absl::Status s = Validate(mesh, overlay, options); !s.ok()) return s;
  absl::StatusOr<Projected> projected = Project(mesh, options);
  if (!projected.ok()) return projected.status();
  const Projected& p = *projected;
  Raster raster(options.size);
  DrawSurface(mesh, p, &raster);
  const double slack = kOverlayDepthSlack * p.depth_range;
  for (const std::vector<int32_t>& ring : overlay.rings) {
    DrawRing(mesh, p, ring, slack, &raster);
  }
  for (int32_t v : overlay.points) DrawPoint(p, v, slack, &raster);
  RgbaImage image;
  image.width = options.size;
  image.height = options.size;
  image.rgba = raster.TakePixels();
  return image;
}

absl::StatusOr<std::string> EncodePng(const RgbaImage& image) {
  if (image.width <= 0 || image.height <= 0 ||
      image.rgba.size() !=
          static_cast<size_t>(image.width) * image.height * 4) {
    return absl::InvalidArgumentError(
        absl::StrCat("png: ", image.rgba.size(), " bytes do not hold a ",
                     image.width, "x", image.height, " RGBA image"));
  }
  std::vector<png_bytep> rows(image.height);
  for (int r = 0; r < image.height; ++r) {
    rows[r] = const_cast<png_bytep>(image.rgba.data()) +
              static_cast<size_t>(r) * image.width * 4;
  }
  std::string out;
  if (!EncodePngRaw(image, rows.data(), &out)) {
    return absl::InternalError("png: libpng failed to encode the thumbnail");
  }
  return out;
}

absl::StatusOr<std::string> RenderThumbnailPng(
    const Mesh& mesh, const ThumbnailOverlay& overlay,
    const ThumbnailOptions& options) {
  absl::StatusOr<RgbaImage> image = RenderThumbnail(mesh, overlay, options);
  if (!image.ok()) return image.status();
  return EncodePng(*image);
}

ThumbnailOverlay OverlayFromExplanation(const Signature& signature,
                                        const Explanation& explanation) {
  ThumbnailOverlay overlay;
  const size_t n =
      std::min(signature.features.size(), explanation.feature_vertices.size());
  for (size_t f = 0; f < n; ++f) {
    const std::vector<int32_t>& vertices = explanation.feature_vertices[f];
    if (vertices.empty()) continue;
    if (signature.features[f].kind == FeatureKind::kPoint) {
      overlay.points.push_back(vertices.front());
    } else {
      overlay.rings.push_back(vertices);
    }
  }
  return overlay;
}

}  // namespace tpr::extract
