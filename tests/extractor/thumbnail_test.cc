// Tests for extractor/lib/thumbnail.h: golden images compared byte for
// byte (tests/data/thumbnails; TPR_UPDATE_GOLDEN=1 rewrites them), and,
// independently of any stored picture, silhouette areas against the
// analytic projected areas of a sphere (a disc) and a cube (a hexagon of
// area |f.x| + |f.y| + |f.z| for a unit cube seen along f), the overlay's
// depth test, determinism, and the PNG decoded by libpng's own reader.
#include "extractor/lib/thumbnail.h"

#include <png.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "extractor/lib/mesh_io.h"
#include "extractor/synth/synth.h"
#include "gtest/gtest.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

constexpr double kPi = 3.14159265358979323846;
const std::string kGoldenDir = std::string(TPR_TEST_DATA_DIR) + "/thumbnails/";

// An axis-aligned cube of edge `edge` centred at `centre`, 12 triangles.
Mesh Cube(double edge = 1.0, Eigen::Vector3d centre = {0, 0, 0}) {
  std::vector<Eigen::Vector3d> p;
  for (int i = 0; i < 8; ++i) {
    p.push_back(centre + edge * Eigen::Vector3d((i & 1) ? 0.5 : -0.5,
                                                (i & 2) ? 0.5 : -0.5,
                                                (i & 4) ? 0.5 : -0.5));
  }
  std::vector<std::vector<int32_t>> quads = {{0, 2, 3, 1}, {4, 5, 7, 6},
                                             {0, 1, 5, 4}, {2, 6, 7, 3},
                                             {0, 4, 6, 2}, {1, 3, 7, 5}};
  absl::StatusOr<LoadedMesh> m = BuildMesh(p, quads, IntakeOptions{});
  EXPECT_TRUE(m.ok()) << m.status();
  return m->mesh;
}

// The synthetic body of the golden set: tpr-synth's biped, rest pose.
Mesh Body() {
  synth::ShapeOptions options;
  options.target_vertices = 3000;
  absl::StatusOr<Mesh> m = synth::GenerateShape("biped_adult", 0, options);
  EXPECT_TRUE(m.ok()) << m.status();
  return *m;
}

// A fixed overlay on the body, independent of extraction: the highest and
// lowest vertices as points, and the vertices in a thin horizontal slab at
// mid-height as a ring.
ThumbnailOverlay BodyOverlay(const Mesh& m) {
  ThumbnailOverlay overlay;
  int32_t top = 0, bottom = 0;
  double lo = m.positions[0].y(), hi = lo;
  for (size_t v = 0; v < m.positions.size(); ++v) {
    const double y = m.positions[v].y();
    if (y > m.positions[top].y()) top = static_cast<int32_t>(v);
    if (y < m.positions[bottom].y()) bottom = static_cast<int32_t>(v);
    lo = std::min(lo, y);
    hi = std::max(hi, y);
  }
  overlay.points = {top, bottom};
  const double mid = (lo + hi) / 2, half_width = (hi - lo) * 0.01;
  std::vector<int32_t> ring;
  for (size_t v = 0; v < m.positions.size(); ++v) {
    if (std::abs(m.positions[v].y() - mid) < half_width) {
      ring.push_back(static_cast<int32_t>(v));
    }
  }
  overlay.rings.push_back(ring);
  return overlay;
}

int64_t OpaquePixels(const RgbaImage& image) {
  int64_t n = 0;
  for (size_t i = 3; i < image.rgba.size(); i += 4) n += image.rgba[i] == 255;
  return n;
}

int64_t PixelsOfColour(const RgbaImage& image, uint8_t r, uint8_t g,
                       uint8_t b) {
  int64_t n = 0;
  for (size_t i = 0; i < image.rgba.size(); i += 4) {
    n += image.rgba[i] == r && image.rgba[i + 1] == g && image.rgba[i + 2] == b;
  }
  return n;
}

void ExpectGolden(const std::string& name, const std::string& png) {
  const std::string path = kGoldenDir + name;
  const char* update = std::getenv("TPR_UPDATE_GOLDEN");
  if (update != nullptr && std::string(update) == "1") {
    std::ofstream(path, std::ios::binary) << png;
  }
  std::ifstream in(path, std::ios::binary);
  ASSERT_TRUE(in) << "missing golden image " << path
                  << " (TPR_UPDATE_GOLDEN=1 writes it)";
  std::stringstream golden;
  golden << in.rdbuf();
  if (golden.str() != png) {
    const std::string actual = ::testing::TempDir() + "actual_" + name;
    std::ofstream(actual, std::ios::binary) << png;
    ADD_FAILURE() << name << " differs from " << path << " (" << png.size()
                  << " vs " << golden.str().size() << " bytes); the render is "
                  << actual;
  }
}

TEST(ThumbnailTest, CubeMatchesGolden) {
  absl::StatusOr<std::string> png =
      RenderThumbnailPng(Cube(), ThumbnailOverlay{}, ThumbnailOptions{});
  ASSERT_TRUE(png.ok()) << png.status();
  ExpectGolden("cube.png", *png);
}

TEST(ThumbnailTest, SphereMatchesGolden) {
  absl::StatusOr<std::string> png = RenderThumbnailPng(
      testing::Icosphere(4), ThumbnailOverlay{}, ThumbnailOptions{});
  ASSERT_TRUE(png.ok()) << png.status();
  ExpectGolden("sphere.png", *png);
}

TEST(ThumbnailTest, BodyWithOverlayMatchesGolden) {
  const Mesh body = Body();
  absl::StatusOr<std::string> png =
      RenderThumbnailPng(body, BodyOverlay(body), ThumbnailOptions{});
  ASSERT_TRUE(png.ok()) << png.status();
  ExpectGolden("body.png", *png);
}

// The sphere's silhouette is a disc whose diameter is the fitted extent,
// size - 2 margin pixels. The icosphere is inscribed in the unit sphere,
// so both its outline and its extent fall short of the disc's by at most
// 1 - cos(half the largest edge angle), about 0.2% at level 5; pixel
// rounding along the outline adds about 0.1%. Tolerance 0.6%.
TEST(ThumbnailTest, SphereSilhouetteIsTheProjectedDisc) {
  for (int size : {128, 256}) {
    ThumbnailOptions options;
    options.size = size;
    absl::StatusOr<RgbaImage> image =
        RenderThumbnail(testing::Icosphere(5, 3.0), {}, options);
    ASSERT_TRUE(image.ok()) << image.status();
    const double radius = (size - 2.0 * options.margin) / 2.0;
    const double expected = kPi * radius * radius;
    EXPECT_NEAR(OpaquePixels(*image), expected, 0.006 * expected)
        << "size " << size;
  }
}

// A unit cube seen along the unit vector f covers |f.x| + |f.y| + |f.z|;
// its screen width is sum |right_i| and height sum |up_i| (each edge
// direction contributes its projected length once), so the fit's scale is
// (size - 2 margin) / max(width, height) pixels per unit. The outline's
// pixel rounding is within 0.3% at this size.
TEST(ThumbnailTest, CubeSilhouetteIsTheProjectedHexagon) {
  const ThumbnailView view = FixedThumbnailView();
  const double width = view.right.cwiseAbs().sum();
  const double height = view.up.cwiseAbs().sum();
  const double face = view.forward.cwiseAbs().sum();
  ThumbnailOptions options;
  const double scale =
      (options.size - 2.0 * options.margin) / std::max(width, height);
  const double expected = face * scale * scale;
  for (double edge : {1.0, 7.5}) {
    absl::StatusOr<RgbaImage> image =
        RenderThumbnail(Cube(edge, {3, -2, 10}), {}, options);
    ASSERT_TRUE(image.ok()) << image.status();
    EXPECT_NEAR(OpaquePixels(*image), expected, 0.003 * expected)
        << "edge " << edge;
  }
}

TEST(ThumbnailTest, ViewIsOrthonormalAndRightHanded) {
  const ThumbnailView v = FixedThumbnailView();
  EXPECT_NEAR(v.right.norm(), 1.0, 1e-15);
  EXPECT_NEAR(v.up.norm(), 1.0, 1e-15);
  EXPECT_NEAR(v.forward.norm(), 1.0, 1e-15);
  EXPECT_NEAR(v.right.dot(v.up), 0.0, 1e-15);
  EXPECT_NEAR(v.right.dot(v.forward), 0.0, 1e-15);
  EXPECT_NEAR(v.up.dot(v.forward), 0.0, 1e-15);
  EXPECT_LT((v.right.cross(v.up) + v.forward).norm(), 1e-15);
  // Three-quarter: from above (looking down) and from the front right.
  EXPECT_LT(v.forward.y(), 0.0);
  EXPECT_LT(v.forward.x(), 0.0);
  EXPECT_LT(v.forward.z(), 0.0);
}

// The picture is centred: the opaque pixels' bounding box sits in the
// middle, its longer side spanning size - 2 margin pixels (to one pixel).
TEST(ThumbnailTest, MeshIsCentredAndFitted) {
  absl::StatusOr<RgbaImage> image = RenderThumbnail(Body(), {}, {});
  ASSERT_TRUE(image.ok()) << image.status();
  int x0 = image->width, x1 = -1, y0 = image->height, y1 = -1;
  for (int y = 0; y < image->height; ++y) {
    for (int x = 0; x < image->width; ++x) {
      if (image->rgba[(static_cast<size_t>(y) * image->width + x) * 4 + 3]) {
        x0 = std::min(x0, x);
        x1 = std::max(x1, x);
        y0 = std::min(y0, y);
        y1 = std::max(y1, y);
      }
    }
  }
  const int span = std::max(x1 - x0 + 1, y1 - y0 + 1);
  EXPECT_NEAR(span, 256 - 16, 1);
  EXPECT_NEAR((x0 + x1 + 1) / 2.0, 128.0, 1.0);
  EXPECT_NEAR((y0 + y1 + 1) / 2.0, 128.0, 1.0);
  // Corners are transparent.
  EXPECT_EQ(image->rgba[3], 0);
  EXPECT_EQ(image->rgba.back(), 0);
}

// A point on the near side of the sphere shows; the same point on the far
// side is hidden by the surface.
TEST(ThumbnailTest, OverlayIsDepthTested) {
  const Mesh sphere = testing::Icosphere(4);
  const ThumbnailView view = FixedThumbnailView();
  int32_t nearest = 0, farthest = 0;
  for (size_t v = 0; v < sphere.positions.size(); ++v) {
    const double d = sphere.positions[v].dot(view.forward);
    if (d < sphere.positions[nearest].dot(view.forward)) nearest = v;
    if (d > sphere.positions[farthest].dot(view.forward)) farthest = v;
  }
  ThumbnailOverlay front, back;
  front.points = {nearest};
  back.points = {farthest};
  absl::StatusOr<RgbaImage> shown = RenderThumbnail(sphere, front, {});
  absl::StatusOr<RgbaImage> hidden = RenderThumbnail(sphere, back, {});
  ASSERT_TRUE(shown.ok() && hidden.ok());
  // A dot of radius 4 pixels: about 50 pixels.
  EXPECT_GT(PixelsOfColour(*shown, 220, 30, 30), 30);
  EXPECT_EQ(PixelsOfColour(*hidden, 220, 30, 30), 0);
  // The equator, seen from 25 degrees above: its near half projects below
  // the image's centre line, its far half above (up to 120 sin 25 = 51
  // rows), behind the surface. Only the near half may show, to within 8
  // rows at the two ends where the halves meet: the band of vertices
  // within 0.05 of the equator is 0.05 cos 25 x 120 = 5.4 rows high there,
  // plus the pen and the depth slack.
  ThumbnailOverlay equator;
  equator.rings.emplace_back();
  for (size_t v = 0; v < sphere.positions.size(); ++v) {
    if (std::abs(sphere.positions[v].y()) < 0.05) {
      equator.rings.back().push_back(static_cast<int32_t>(v));
    }
  }
  absl::StatusOr<RgbaImage> ring = RenderThumbnail(sphere, equator, {});
  ASSERT_TRUE(ring.ok());
  int64_t near_half = 0, far_half = 0;
  for (int y = 0; y < ring->height; ++y) {
    for (int x = 0; x < ring->width; ++x) {
      const uint8_t* p =
          &ring->rgba[(static_cast<size_t>(y) * ring->width + x) * 4];
      if (p[0] != 25 || p[1] != 25 || p[2] != 25) continue;
      (y >= 128 - 8 ? near_half : far_half)++;
    }
  }
  // The near half is about half an ellipse of semi-axes 120 and
  // 120 sin 25 degrees: about 280 pixels long, drawn 2 wide.
  EXPECT_GT(near_half, 280);
  EXPECT_EQ(far_half, 0);
}

TEST(ThumbnailTest, SameInputSameBytesOnEveryThread) {
  const Mesh body = Body();
  const ThumbnailOverlay overlay = BodyOverlay(body);
  absl::StatusOr<std::string> first =
      RenderThumbnailPng(body, overlay, ThumbnailOptions{});
  ASSERT_TRUE(first.ok()) << first.status();
  std::vector<std::string> others(4);
  std::vector<std::thread> threads;
  for (std::string& out : others) {
    threads.emplace_back([&] {
      absl::StatusOr<std::string> png =
          RenderThumbnailPng(body, overlay, ThumbnailOptions{});
      if (png.ok()) out = *png;
    });
  }
  for (std::thread& t : threads) t.join();
  for (const std::string& out : others) EXPECT_EQ(out, *first);
}

// libpng's own reader decodes the PNG to the rendered pixels.
TEST(ThumbnailTest, PngDecodesToTheImage) {
  absl::StatusOr<RgbaImage> image = RenderThumbnail(Cube(), {}, {});
  ASSERT_TRUE(image.ok()) << image.status();
  absl::StatusOr<std::string> png = EncodePng(*image);
  ASSERT_TRUE(png.ok()) << png.status();
  png_image decoded{};
  decoded.version = PNG_IMAGE_VERSION;
  ASSERT_TRUE(
      png_image_begin_read_from_memory(&decoded, png->data(), png->size()));
  EXPECT_EQ(decoded.width, 256u);
  EXPECT_EQ(decoded.height, 256u);
  decoded.format = PNG_FORMAT_RGBA;
  std::vector<uint8_t> pixels(PNG_IMAGE_SIZE(decoded));
  ASSERT_TRUE(
      png_image_finish_read(&decoded, nullptr, pixels.data(), 0, nullptr));
  EXPECT_EQ(pixels, image->rgba);
  // No time chunk: the bytes cannot depend on when they were made.
  EXPECT_EQ(png->find("tIME"), std::string::npos);
}

TEST(ThumbnailTest, OverlayFromExplanationSplitsPointsAndRings) {
  Signature s;
  s.features.resize(3);
  s.features[2].kind = FeatureKind::kRing;
  Explanation e;
  e.feature_vertices = {{4}, {}, {7, 8, 9}};
  const ThumbnailOverlay o = OverlayFromExplanation(s, e);
  EXPECT_EQ(o.points, std::vector<int32_t>({4}));
  ASSERT_EQ(o.rings.size(), 1u);
  EXPECT_EQ(o.rings[0], std::vector<int32_t>({7, 8, 9}));
}

TEST(ThumbnailTest, BadInputIsRefusedByName) {
  ThumbnailOptions small;
  small.size = 8;
  EXPECT_EQ(RenderThumbnail(Cube(), {}, small).status().code(),
            absl::StatusCode::kInvalidArgument);
  ThumbnailOptions wide;
  wide.margin = 100;
  EXPECT_EQ(RenderThumbnail(Cube(), {}, wide).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(RenderThumbnail(Mesh{}, {}, {}).status().code(),
            absl::StatusCode::kInvalidArgument);
  ThumbnailOverlay bad;
  bad.points = {8};
  absl::Status s = RenderThumbnail(Cube(), bad, {}).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("point vertex 8"), std::string::npos) << s;
  Mesh flat;
  flat.positions = {{1, 1, 1}, {1, 1, 1}, {1, 1, 1}};
  flat.triangles = {{0, 1, 2}};
  s = RenderThumbnail(flat, {}, {}).status();
  EXPECT_NE(s.message().find("single point"), std::string::npos) << s;
  Mesh nan = Cube();
  nan.positions[3].x() = std::nan("");
  s = RenderThumbnail(nan, {}, {}).status();
  EXPECT_NE(s.message().find("vertex 3 is not finite"), std::string::npos) << s;
}

}  // namespace
}  // namespace tpr::extract
