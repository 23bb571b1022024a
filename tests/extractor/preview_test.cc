// Tests for extractor/lib/preview.h: the face limit, that every preview
// vertex is one of the mesh's (halfedge collapses move none), that the
// simplified surface stays close to the original (area, bounding box), and
// that the PLY reads back through the project's own reader (mesh_io.h)
// with the same counts and float coordinates.
#include "extractor/lib/preview.h"

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>
#include <set>
#include <string>
#include <tuple>

#include "extractor/lib/mesh_io.h"
#include "extractor/synth/synth.h"
#include "gtest/gtest.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

Mesh Body(int vertices) {
  synth::ShapeOptions options;
  options.target_vertices = vertices;
  absl::StatusOr<Mesh> m = synth::GenerateShape("biped_adult", 0, options);
  EXPECT_TRUE(m.ok()) << m.status();
  return *m;
}

// The signed volume a closed, outward-oriented mesh encloses.
double Volume(const Mesh& m) {
  double six = 0;
  for (const auto& t : m.triangles) {
    six += m.positions[t[0]].dot(m.positions[t[1]].cross(m.positions[t[2]]));
  }
  return six / 6;
}

using FloatPoint = std::tuple<float, float, float>;

FloatPoint AsFloat(const Eigen::Vector3d& p) {
  return {static_cast<float>(p.x()), static_cast<float>(p.y()),
          static_cast<float>(p.z())};
}

TEST(PreviewTest, BodyIsSimplifiedUnderTheLimitWithItsOwnVertices) {
  for (int vertices : {10000, 30000}) {
    const Mesh body = Body(vertices);
    ASSERT_GT(body.triangles.size(), 5000u);
    absl::StatusOr<Mesh> preview = SimplifyForPreview(body, PreviewOptions{});
    ASSERT_TRUE(preview.ok()) << preview.status();
    EXPECT_LE(preview->triangles.size(), 5000u);
    EXPECT_GE(preview->triangles.size(), 4900u);  // the decimater gets close
    std::set<FloatPoint> original;
    for (const Eigen::Vector3d& p : body.positions) original.insert(AsFloat(p));
    for (const Eigen::Vector3d& p : preview->positions) {
      ASSERT_TRUE(original.count(AsFloat(p))) << p.transpose();
    }
    // Genus 0 closed surface in, genus 0 closed surface out.
    const MeshStats before = ComputeMeshStats(body);
    const MeshStats after = ComputeMeshStats(*preview);
    EXPECT_EQ(after.genus, before.genus);
    EXPECT_EQ(after.boundary_edges, 0);
    EXPECT_EQ(after.components, before.components);
    // Quadric collapses keep the shape: area and enclosed volume within 3%.
    EXPECT_NEAR(after.area, before.area, 0.03 * before.area);
    const double volume = Volume(body);
    EXPECT_NEAR(Volume(*preview), volume, 0.03 * std::abs(volume));
  }
}

TEST(PreviewTest, PlyReadsBackThroughIntake) {
  const Mesh body = Body(10000);
  absl::StatusOr<Mesh> preview = SimplifyForPreview(body, PreviewOptions{});
  ASSERT_TRUE(preview.ok()) << preview.status();
  const std::string ply = EncodePreviewPly(*preview);
  const size_t header = ply.find("end_header\n") + std::strlen("end_header\n");
  EXPECT_EQ(ply.size(), header + preview->positions.size() * 12 +
                            preview->triangles.size() * 13);
  EXPECT_EQ(ply.rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
  absl::StatusOr<LoadedMesh> back =
      LoadMeshFromBuffer(ply, MeshFormat::kPly, "preview.ply", IntakeOptions{});
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->mesh.positions.size(), preview->positions.size());
  ASSERT_EQ(back->mesh.triangles.size(), preview->triangles.size());
  for (size_t v = 0; v < preview->positions.size(); ++v) {
    EXPECT_EQ(AsFloat(back->mesh.positions[v]), AsFloat(preview->positions[v]))
        << "vertex " << v;
  }
  // The same mesh, the same bytes.
  absl::StatusOr<std::string> again = MakePreviewPly(body, PreviewOptions{});
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(*again, ply);
}

TEST(PreviewTest, SmallMeshIsKeptAsItIs) {
  const Mesh sphere = testing::Icosphere(3);  // 1280 triangles
  absl::StatusOr<Mesh> preview = SimplifyForPreview(sphere, PreviewOptions{});
  ASSERT_TRUE(preview.ok()) << preview.status();
  EXPECT_EQ(preview->triangles, sphere.triangles);
  EXPECT_EQ(preview->positions, sphere.positions);
}

TEST(PreviewTest, LimitIsAnOption) {
  PreviewOptions options;
  options.max_faces = 500;
  absl::StatusOr<Mesh> preview =
      SimplifyForPreview(testing::Icosphere(4), options);
  ASSERT_TRUE(preview.ok()) << preview.status();
  EXPECT_LE(preview->triangles.size(), 500u);
  options.max_faces = 3;
  EXPECT_EQ(SimplifyForPreview(testing::Icosphere(1), options).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// Many closed tetrahedra cannot lose a face each without breaking their
// topology: the limit cannot be met, and the error says so.
TEST(PreviewTest, UnreachableLimitIsFailedPrecondition) {
  Mesh many;
  for (int k = 0; k < 100; ++k) {
    const int32_t b = static_cast<int32_t>(many.positions.size());
    const double x = 3.0 * k;
    many.positions.insert(many.positions.end(),
                          {{x, 0, 0}, {x + 1, 0, 0}, {x, 1, 0}, {x, 0, 1}});
    many.triangles.insert(many.triangles.end(), {{b, b + 2, b + 1},
                                                 {b, b + 1, b + 3},
                                                 {b, b + 3, b + 2},
                                                 {b + 1, b + 2, b + 3}});
  }
  PreviewOptions options;
  options.max_faces = 100;
  absl::Status s = SimplifyForPreview(many, options).status();
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition) << s;
  EXPECT_NE(s.message().find("above the limit of 100"), std::string::npos) << s;
}

}  // namespace
}  // namespace tpr::extract
