// Tests for extractor/lib/mesh_writer.h: exact bytes for a hand-made mesh
// (the formats are simple enough to write the expected text by hand), the
// binary layout by size and by decoding it here, and round trips through
// intake (mesh_io.h).
#include "extractor/lib/mesh_writer.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "extractor/lib/mesh_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tpr::extract {
namespace {

// A tetrahedron, outward oriented.
Mesh Tetrahedron() {
  Mesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 0.1}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return m;
}

TEST(MeshWriterTest, OffIsExact) {
  MeshWriteOptions options;
  absl::StatusOr<std::string> out = WriteMeshToString(Tetrahedron(), options);
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(*out,
            "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 0.1\n"
            "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n");
}

TEST(MeshWriterTest, ColouredOffIsCoff) {
  MeshWriteOptions options;
  options.vertex_colors = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {1, 2, 3}};
  absl::StatusOr<std::string> out = WriteMeshToString(Tetrahedron(), options);
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(*out,
            "COFF\n4 4 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n"
            "0 1 0 0 0 255 255\n0 0 0.1 1 2 3 255\n"
            "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n");
}

TEST(MeshWriterTest, AsciiPlyWithColoursIsExact) {
  MeshWriteOptions options;
  options.format = MeshWriteFormat::kPlyAscii;
  options.vertex_colors = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {1, 2, 3}};
  absl::StatusOr<std::string> out = WriteMeshToString(Tetrahedron(), options);
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(*out,
            "ply\nformat ascii 1.0\ncomment written by TPR Search\n"
            "element vertex 4\nproperty double x\nproperty double y\n"
            "property double z\nproperty uchar red\nproperty uchar green\n"
            "property uchar blue\nelement face 4\n"
            "property list uchar int vertex_indices\nend_header\n"
            "0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 255\n0 0 0.1 1 2 3\n"
            "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n");
}

TEST(MeshWriterTest, FewerDigitsDeclareFloat) {
  Mesh m = Tetrahedron();
  m.positions[3].z() = 1.0 / 3.0;
  MeshWriteOptions options;
  options.format = MeshWriteFormat::kPlyAscii;
  options.digits = 6;
  absl::StatusOr<std::string> out = WriteMeshToString(m, options);
  ASSERT_TRUE(out.ok());
  EXPECT_NE(out->find("property float x\n"), std::string::npos);
  EXPECT_NE(out->find("\n0 0 0.333333\n"), std::string::npos);
  options.digits = 17;
  out = WriteMeshToString(m, options);
  ASSERT_TRUE(out.ok());
  EXPECT_NE(out->find("\n0 0 0.3333333333333333\n"), std::string::npos);
}

TEST(MeshWriterTest, BinaryPlyDecodesToTheSameDoubles) {
  Mesh m = Tetrahedron();
  m.positions[1].x() = 0.1 + 0.2;  // not exactly representable in decimal
  MeshWriteOptions options;
  options.format = MeshWriteFormat::kPlyBinary;
  options.vertex_colors = {{9, 8, 7}, {6, 5, 4}, {3, 2, 1}, {0, 0, 0}};
  absl::StatusOr<std::string> out = WriteMeshToString(m, options);
  ASSERT_TRUE(out.ok());
  const std::string end = "end_header\n";
  const size_t body = out->find(end);
  ASSERT_NE(body, std::string::npos);
  EXPECT_NE(out->find("format binary_little_endian 1.0\n"), std::string::npos);
  const size_t start = body + end.size();
  // Per vertex 3 doubles + 3 bytes; per face 1 count byte + 3 int32.
  ASSERT_EQ(out->size(), start + 4 * (24 + 3) + 4 * (1 + 12));
  // Decode on a little-endian host (the only kind this project builds on).
  const uint16_t probe = 1;
  uint8_t low;
  std::memcpy(&low, &probe, 1);
  if (low != 1) GTEST_SKIP() << "big-endian host";
  for (int v = 0; v < 4; ++v) {
    for (int a = 0; a < 3; ++a) {
      double d;
      std::memcpy(&d, out->data() + start + v * 27 + a * 8, 8);
      EXPECT_EQ(d, m.positions[v][a]);
    }
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(static_cast<uint8_t>((*out)[start + v * 27 + 24 + c]),
                options.vertex_colors[v][c]);
    }
  }
  const size_t faces = start + 4 * 27;
  for (int f = 0; f < 4; ++f) {
    EXPECT_EQ((*out)[faces + f * 13], 3);
    for (int i = 0; i < 3; ++i) {
      int32_t id;
      std::memcpy(&id, out->data() + faces + f * 13 + 1 + 4 * i, 4);
      EXPECT_EQ(id, m.triangles[f][i]);
    }
  }
}

TEST(MeshWriterTest, RoundTripsThroughIntake) {
  Mesh m = Tetrahedron();
  m.positions[2] = Eigen::Vector3d(0.1 + 0.2, 1.0 / 3.0, -2.5e-3);
  for (MeshWriteFormat format :
       {MeshWriteFormat::kOff, MeshWriteFormat::kPlyAscii,
        MeshWriteFormat::kPlyBinary}) {
    for (bool colours : {false, true}) {
      if (format == MeshWriteFormat::kOff && colours)
        continue;  // COFF: see below
      MeshWriteOptions options;
      options.format = format;
      if (colours) options.vertex_colors.assign(4, Rgb{10, 20, 30});
      absl::StatusOr<std::string> out = WriteMeshToString(m, options);
      ASSERT_TRUE(out.ok());
      absl::StatusOr<LoadedMesh> loaded = LoadMeshFromBuffer(
          *out, MeshFormat::kUnknown,
          format == MeshWriteFormat::kOff ? "t.off" : "t.ply", IntakeOptions{});
      ASSERT_TRUE(loaded.ok())
          << static_cast<int>(format) << " " << loaded.status();
      ASSERT_EQ(loaded->mesh.positions.size(), 4u);
      ASSERT_EQ(loaded->mesh.triangles.size(), 4u);
      EXPECT_EQ(loaded->stats.boundary_edges, 0);
      EXPECT_EQ(loaded->stats.genus, 0);
      for (int v = 0; v < 4; ++v) {
        // Intake keeps coordinates as floats (OpenMesh's readers).
        for (int a = 0; a < 3; ++a) {
          EXPECT_EQ(loaded->mesh.positions[v][a],
                    static_cast<double>(static_cast<float>(m.positions[v][a])));
        }
      }
      EXPECT_EQ(loaded->mesh.triangles, m.triangles);
    }
  }
}

TEST(MeshWriterTest, SameInputSameBytes) {
  MeshWriteOptions options;
  options.format = MeshWriteFormat::kPlyBinary;
  EXPECT_EQ(*WriteMeshToString(Tetrahedron(), options),
            *WriteMeshToString(Tetrahedron(), options));
}

TEST(MeshWriterTest, BadInputIsInvalidArgument) {
  MeshWriteOptions options;
  Mesh bad_index = Tetrahedron();
  bad_index.triangles[2][1] = 4;
  absl::StatusOr<std::string> out = WriteMeshToString(bad_index, options);
  EXPECT_EQ(out.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(out.status().message().find("triangle 2"), absl::string_view::npos);

  Mesh negative = Tetrahedron();
  negative.triangles[0][0] = -1;
  EXPECT_EQ(WriteMeshToString(negative, options).status().code(),
            absl::StatusCode::kInvalidArgument);

  Mesh nan = Tetrahedron();
  nan.positions[1].y() = std::nan("");
  out = WriteMeshToString(nan, options);
  EXPECT_EQ(out.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(out.status().message().find("vertex 1"), absl::string_view::npos);

  MeshWriteOptions colours;
  colours.vertex_colors.assign(3, Rgb{0, 0, 0});
  EXPECT_EQ(WriteMeshToString(Tetrahedron(), colours).status().code(),
            absl::StatusCode::kInvalidArgument);

  MeshWriteOptions digits;
  digits.digits = 3;
  EXPECT_EQ(WriteMeshToString(Tetrahedron(), digits).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(MeshWriterTest, WritesFilesAndReportsUnwritablePaths) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      ("tpr_mesh_writer_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "t.off").string();
  MeshWriteOptions options;
  ASSERT_TRUE(WriteMeshToFile(Tetrahedron(), options, path).ok());
  std::ifstream in(path, std::ios::binary);
  std::stringstream content;
  content << in.rdbuf();
  EXPECT_EQ(content.str(), *WriteMeshToString(Tetrahedron(), options));
  const absl::Status missing = WriteMeshToFile(
      Tetrahedron(), options, (dir / "no_such_dir" / "t.off").string());
  // Not retryable (UNAVAILABLE would be), and the message names the path
  // and the reason.
  EXPECT_EQ(missing.code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(missing.message()),
              ::testing::HasSubstr("no_such_dir/t.off"));
  EXPECT_THAT(std::string(missing.message()),
              ::testing::HasSubstr("No such file or directory"));
  const absl::Status is_dir =
      WriteMeshToFile(Tetrahedron(), options, dir.string());
  EXPECT_EQ(is_dir.code(), absl::StatusCode::kFailedPrecondition) << is_dir;
  EXPECT_THAT(std::string(is_dir.message()),
              ::testing::HasSubstr("Is a directory"));
  // /dev/full fails every write with ENOSPC: a full disk.
  if (std::filesystem::exists("/dev/full")) {
    const absl::Status full =
        WriteMeshToFile(Tetrahedron(), options, "/dev/full");
    EXPECT_EQ(full.code(), absl::StatusCode::kResourceExhausted) << full;
    EXPECT_THAT(std::string(full.message()),
                ::testing::HasSubstr("No space left"));
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tpr::extract
