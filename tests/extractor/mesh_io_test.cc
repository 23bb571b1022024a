// Tests for mesh intake (extractor/lib/mesh_io.h) and ComputeMeshStats.
// Oracles: analytic counts, areas and genera of hand-made solids; a brute
// force area sum; the same mesh read from every format and built in code.
// The corpus in tests/data/meshes is written by
// tests/data/meshes/make_meshes.py.
#include "extractor/lib/mesh_io.h"

#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "extractor/lib/mesh.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tpr::extract {
namespace {

using ::testing::HasSubstr;

const std::string kDir = std::string(TPR_TEST_DATA_DIR) + "/meshes/";
constexpr double kTetraArea = 1.5 + 0.8660254037844386;  // 3 x 1/2 + sqrt(3)/2

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

double BruteForceArea(const Mesh& mesh) {
  double area = 0;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.positions[t[0]], b = mesh.positions[t[1]],
                          c = mesh.positions[t[2]];
    // Heron's formula: independent of the cross product used by the library.
    const double x = (b - a).norm(), y = (c - b).norm(), z = (a - c).norm();
    const double s = 0.5 * (x + y + z);
    area += std::sqrt(std::max(0.0, s * (s - x) * (s - y) * (s - z)));
  }
  return area;
}

// Every directed edge at most once = consistently oriented (manifold mesh).
bool ConsistentlyOriented(const Mesh& mesh) {
  std::set<std::pair<int32_t, int32_t>> directed;
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      if (!directed.insert({t[k], t[(k + 1) % 3]}).second) return false;
    }
  }
  return true;
}

double SignedVolume(const Mesh& mesh) {
  double v = 0;
  for (const auto& t : mesh.triangles) {
    v += mesh.positions[t[0]].dot(
             mesh.positions[t[1]].cross(mesh.positions[t[2]])) /
         6.0;
  }
  return v;
}

struct Expected {
  std::string file;
  int64_t vertices, faces;
  double area;
  int64_t boundary_edges, components, genus;
};

class GoodFileTest : public ::testing::TestWithParam<Expected> {};

TEST_P(GoodFileTest, LoadsWithKnownCountsAreaAndGenus) {
  const Expected& e = GetParam();
  absl::StatusOr<LoadedMesh> m = LoadMeshFromFile(kDir + "good/" + e.file, {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->stats.vertices, e.vertices);
  EXPECT_EQ(m->stats.faces, e.faces);
  EXPECT_EQ(static_cast<int64_t>(m->mesh.positions.size()), e.vertices);
  EXPECT_EQ(static_cast<int64_t>(m->mesh.triangles.size()), e.faces);
  EXPECT_NEAR(m->stats.area, e.area, 1e-6);
  EXPECT_NEAR(BruteForceArea(m->mesh), e.area, 1e-6);
  EXPECT_EQ(m->stats.boundary_edges, e.boundary_edges);
  EXPECT_EQ(m->stats.components, e.components);
  EXPECT_EQ(m->stats.genus, e.genus);
  EXPECT_TRUE(ConsistentlyOriented(m->mesh));
  if (e.boundary_edges == 0) {
    EXPECT_GT(SignedVolume(m->mesh), 0);
  }
}

TEST_P(GoodFileTest, BufferLoadingMatchesFileLoading) {
  const Expected& e = GetParam();
  const std::string bytes = ReadBytes(kDir + "good/" + e.file);
  absl::StatusOr<LoadedMesh> from_file =
      LoadMeshFromFile(kDir + "good/" + e.file, {});
  // Format guessed from the bytes alone (no name).
  absl::StatusOr<LoadedMesh> guessed =
      LoadMeshFromBuffer(bytes, MeshFormat::kUnknown, "", {});
  ASSERT_TRUE(from_file.ok()) << from_file.status();
  ASSERT_TRUE(guessed.ok()) << guessed.status();
  EXPECT_EQ(guessed->mesh.positions, from_file->mesh.positions);
  EXPECT_EQ(guessed->mesh.triangles, from_file->mesh.triangles);
  EXPECT_EQ(guessed->stats.genus, from_file->stats.genus);
}

INSTANTIATE_TEST_SUITE_P(
    Corpus, GoodFileTest,
    ::testing::Values(
        Expected{"tetrahedron.off", 4, 4, kTetraArea, 0, 1, 0},
        Expected{"cube_quads.obj", 8, 12, 6.0, 0, 1, 0},
        Expected{"hex_prism_ngons.obj", 12, 20, 6.0 + 3.0 * std::sqrt(3.0), 0,
                 1, 0},
        Expected{"cube_ascii.ply", 8, 12, 6.0, 0, 1, 0},
        Expected{"cube_binary_le.ply", 8, 12, 6.0, 0, 1, 0},
        Expected{"cube_binary_be.ply", 8, 12, 6.0, 0, 1, 0},
        Expected{"tetrahedron_ascii.stl", 4, 4, kTetraArea, 0, 1, 0},
        Expected{"cube_binary.stl", 8, 12, 6.0, 0, 1, 0},
        Expected{"grid_with_boundary.off", 9, 8, 4.0, 8, 1, 0},
        Expected{"two_tetrahedra.obj", 8, 8, 2 * kTetraArea, 0, 2, 0}),
    [](const ::testing::TestParamInfo<Expected>& info) {
      std::string name = info.param.file;
      for (char& c : name) {
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
      }
      return name;
    });

TEST(MeshIoTest, AllCubeFormatsGiveTheSameSurface) {
  // Same cube in five encodings: identical vertex sets and triangle areas.
  std::vector<std::string> files = {"cube_quads.obj", "cube_ascii.ply",
                                    "cube_binary_le.ply", "cube_binary_be.ply",
                                    "cube_binary.stl"};
  for (const std::string& f : files) {
    absl::StatusOr<LoadedMesh> m = LoadMeshFromFile(kDir + "good/" + f, {});
    ASSERT_TRUE(m.ok()) << f << ": " << m.status();
    std::set<std::array<double, 3>> corners;
    for (const auto& p : m->mesh.positions)
      corners.insert({p.x(), p.y(), p.z()});
    std::set<std::array<double, 3>> expected;
    for (int z = 0; z < 2; ++z)
      for (int y = 0; y < 2; ++y)
        for (int x = 0; x < 2; ++x)
          expected.insert({1.0 * x, 1.0 * y, 1.0 * z});
    EXPECT_EQ(corners, expected) << f;
    EXPECT_NEAR(SignedVolume(m->mesh), 1.0, 1e-9) << f;
  }
}

TEST(MeshIoTest, DropsDegenerateAndDuplicateFacesAndUnusedVertices) {
  absl::StatusOr<LoadedMesh> m =
      LoadMeshFromFile(kDir + "good/tetra_degenerate_duplicate.off", {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->stats.faces, 4);
  EXPECT_EQ(m->stats.vertices, 4);
  EXPECT_EQ(m->stats.dropped_degenerate_faces, 2);  // collinear + repeated id
  EXPECT_EQ(m->stats.dropped_duplicate_faces, 1);
  EXPECT_EQ(m->stats.unreferenced_vertices, 2);  // midpoint + unused vertex
  EXPECT_EQ(m->stats.genus, 0);
  EXPECT_NEAR(m->stats.area, kTetraArea, 1e-9);
  EXPECT_THAT(m->warnings, ::testing::Contains(HasSubstr("2 degenerate")));
  EXPECT_THAT(m->warnings, ::testing::Contains(HasSubstr("1 duplicate")));
  EXPECT_THAT(m->warnings,
              ::testing::Contains(HasSubstr("removed 2 vertices")));
}

TEST(MeshIoTest, StlDegenerateFacetDroppedByWeldingIsCounted) {
  // A facet whose corners weld together never reaches the importer; it must
  // still be counted.
  std::string bytes = ReadBytes(kDir + "good/tetrahedron_ascii.stl");
  const std::string extra =
      "solid extra\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n"
      "   vertex 0 0 0\n   vertex 1 0 0\n  endloop\n endfacet\nendsolid "
      "extra\n";
  absl::StatusOr<LoadedMesh> m =
      LoadMeshFromBuffer(bytes + extra, MeshFormat::kStl, "", {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->stats.faces, 4);
  EXPECT_EQ(m->stats.dropped_degenerate_faces, 1);
}

TEST(MeshIoTest, ReorientsAFlippedFace) {
  absl::StatusOr<LoadedMesh> m =
      LoadMeshFromFile(kDir + "good/tetra_one_flipped.off", {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_TRUE(ConsistentlyOriented(m->mesh));
  EXPECT_GT(SignedVolume(m->mesh), 0);
  EXPECT_THAT(m->warnings, ::testing::Contains(HasSubstr("reoriented 1")));
}

TEST(MeshIoTest, InsideOutClosedMeshIsTurnedOutward) {
  std::vector<Eigen::Vector3d> v = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  std::vector<std::vector<int32_t>> f = {
      {0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}};  // all inward
  absl::StatusOr<LoadedMesh> m = BuildMesh(v, f, {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_GT(SignedVolume(m->mesh), 0);
}

// A torus as an n x m grid of quads, written by hand: V = nm, F = 2nm,
// genus 1.
void Torus(int n, int m, std::vector<Eigen::Vector3d>* v,
           std::vector<std::vector<int32_t>>* f) {
  const double kPi = 3.14159265358979323846;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j) {
      const double a = 2 * kPi * i / n, b = 2 * kPi * j / m;
      v->emplace_back((2 + std::cos(b)) * std::cos(a),
                      (2 + std::cos(b)) * std::sin(a), std::sin(b));
    }
  }
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < m; ++j) {
      const int a = i * m + j, b = ((i + 1) % n) * m + j,
                c = ((i + 1) % n) * m + (j + 1) % m, d = i * m + (j + 1) % m;
      f->push_back({a, b, c, d});
    }
  }
}

TEST(MeshIoTest, TorusBuiltInCodeHasGenusOne) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::vector<int32_t>> f;
  Torus(24, 12, &v, &f);
  absl::StatusOr<LoadedMesh> m = BuildMesh(v, f, {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->stats.vertices, 24 * 12);
  EXPECT_EQ(m->stats.faces, 2 * 24 * 12);
  EXPECT_EQ(m->stats.genus, 1);
  EXPECT_EQ(m->stats.components, 1);
  EXPECT_EQ(m->stats.boundary_edges, 0);
  EXPECT_NEAR(m->stats.area, BruteForceArea(m->mesh), 1e-9);
  // Inscribed polyhedron: a little below the smooth torus area 8 pi^2.
  EXPECT_LT(m->stats.area, 8 * M_PI * M_PI);
  EXPECT_GT(m->stats.area, 0.95 * 8 * M_PI * M_PI);
}

TEST(MeshIoTest, TorusWrittenToOffAndObjLoadsWithGenusOne) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::vector<int32_t>> f;
  Torus(16, 8, &v, &f);
  std::ostringstream off, obj;
  off.precision(17);
  obj.precision(17);
  off << "OFF\n" << v.size() << " " << f.size() << " 0\n";
  for (const auto& p : v) {
    off << p.x() << " " << p.y() << " " << p.z() << "\n";
    obj << "v " << p.x() << " " << p.y() << " " << p.z() << "\n";
  }
  for (const auto& q : f) {
    off << "4 " << q[0] << " " << q[1] << " " << q[2] << " " << q[3] << "\n";
    obj << "f " << q[0] + 1 << " " << q[1] + 1 << " " << q[2] + 1 << " "
        << q[3] + 1 << "\n";
  }
  const std::string path =
      (std::filesystem::temp_directory_path() / "tpr_mesh_io_test_torus.off")
          .string();
  {
    std::ofstream out(path);
    out << off.str();
  }
  absl::StatusOr<LoadedMesh> from_file = LoadMeshFromFile(path, {});
  std::remove(path.c_str());
  absl::StatusOr<LoadedMesh> from_obj =
      LoadMeshFromBuffer(obj.str(), MeshFormat::kObj, "", {});
  for (const auto* m : {&from_file, &from_obj}) {
    ASSERT_TRUE(m->ok()) << m->status();
    EXPECT_EQ((*m)->stats.genus, 1);
    EXPECT_EQ((*m)->stats.vertices, 16 * 8);
    EXPECT_EQ((*m)->stats.faces, 2 * 16 * 8);
  }
}

TEST(MeshIoTest, GenusTwoFromTwoToriJoinedByATube) {
  // Genus is additive over components: two tori side by side give 2.
  std::vector<Eigen::Vector3d> v, v2;
  std::vector<std::vector<int32_t>> f, f2;
  Torus(12, 6, &v, &f);
  Torus(12, 6, &v2, &f2);
  const int32_t offset = static_cast<int32_t>(v.size());
  for (auto& p : v2) v.push_back(p + Eigen::Vector3d(10, 0, 0));
  for (auto q : f2) {
    for (auto& i : q) i += offset;
    f.push_back(q);
  }
  absl::StatusOr<LoadedMesh> m = BuildMesh(v, f, {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->stats.components, 2);
  EXPECT_EQ(m->stats.genus, 2);
}

TEST(MeshIoTest, AnnulusHasTwoBoundaryLoopsAndGenusZero) {
  // Ring of 8 quads between radius 1 and 2: chi = 0, B = 2, genus 0.
  std::vector<Eigen::Vector3d> v;
  std::vector<std::vector<int32_t>> f;
  for (int i = 0; i < 8; ++i) {
    const double a = 2 * M_PI * i / 8;
    v.emplace_back(std::cos(a), std::sin(a), 0);
    v.emplace_back(2 * std::cos(a), 2 * std::sin(a), 0);
  }
  for (int i = 0; i < 8; ++i) {
    const int j = (i + 1) % 8;
    f.push_back({2 * i, 2 * i + 1, 2 * j + 1, 2 * j});
  }
  absl::StatusOr<LoadedMesh> m = BuildMesh(v, f, {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->stats.boundary_edges, 16);
  EXPECT_EQ(m->stats.genus, 0);
}

TEST(MeshIoTest, MobiusStripIsCutOpenToOrient) {
  // 6 quads around a strip with a half twist.
  std::vector<Eigen::Vector3d> v;
  const int n = 6;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n, t = a / 2;
    for (double s : {-0.3, 0.3}) {
      v.emplace_back((1 + s * std::cos(t)) * std::cos(a),
                     (1 + s * std::cos(t)) * std::sin(a), s * std::sin(t));
    }
  }
  std::vector<std::vector<int32_t>> f;
  for (int i = 0; i + 1 < n; ++i) {
    f.push_back({2 * i, 2 * i + 1, 2 * i + 3, 2 * i + 2});
  }
  f.push_back({2 * (n - 1), 2 * (n - 1) + 1, 0, 1});  // glued with a twist
  // Was INVALID_ARGUMENT ("non-orientable"). Now every mesh that can be
  // read is indexed: the strip is cut open along one edge into a band that
  // orients consistently (mesh_repair_test.cc has the full counts).
  absl::StatusOr<LoadedMesh> m = BuildMesh(v, f, {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_TRUE(ConsistentlyOriented(m->mesh));
  EXPECT_EQ(m->stats.orientation_cuts, 1);
  EXPECT_EQ(m->stats.faces, 2 * n);
  EXPECT_THAT(m->warnings,
              ::testing::Contains(HasSubstr("1 edges cut open to orient")));
}

TEST(MeshIoTest, BuildMeshRejectsBadInputNamingTheElement) {
  const std::vector<Eigen::Vector3d> v = {
      {0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const std::vector<std::vector<int32_t>> tetra = {
      {0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  {
    auto bad = v;
    bad[2].y() = std::nan("");
    auto m = BuildMesh(bad, tetra, {});
    EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(m.status().message(), HasSubstr("vertex 2 has a non-finite"));
  }
  {
    auto f = tetra;
    f[3][1] = 7;
    auto m = BuildMesh(v, f, {});
    EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(m.status().message(), HasSubstr("face 3 references vertex 7"));
  }
  {
    auto f = tetra;
    f[1] = {0, 1};
    auto m = BuildMesh(v, f, {});
    EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(m.status().message(), HasSubstr("face 1 has 2 vertices"));
  }
  {
    auto m = BuildMesh({}, {}, {});
    EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(m.status().message(), HasSubstr("no vertices"));
  }
  {
    auto m = BuildMesh(v, {{0, 1, 1}}, {});
    EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(m.status().message(), HasSubstr("no faces left"));
  }
}

TEST(MeshIoTest, SizeLimitsAreResourceExhausted) {
  IntakeOptions few_vertices;
  few_vertices.max_vertices = 7;
  IntakeOptions few_faces;
  few_faces.max_faces = 11;
  for (const std::string f :
       {"cube_quads.obj", "cube_ascii.ply", "cube_binary_le.ply",
        "cube_binary_be.ply", "cube_binary.stl"}) {
    auto m = LoadMeshFromFile(kDir + "good/" + f, few_vertices);
    EXPECT_EQ(m.status().code(), absl::StatusCode::kResourceExhausted) << f;
    EXPECT_THAT(m.status().message(), HasSubstr("max_vertices")) << f;
    m = LoadMeshFromFile(kDir + "good/" + f, few_faces);
    EXPECT_EQ(m.status().code(), absl::StatusCode::kResourceExhausted) << f;
    EXPECT_THAT(m.status().message(), HasSubstr("max_faces")) << f;
  }
  // Exactly at the limit is fine.
  IntakeOptions exact;
  exact.max_vertices = 8;
  exact.max_faces = 12;
  EXPECT_TRUE(LoadMeshFromFile(kDir + "good/cube_quads.obj", exact).ok());
  // BuildMesh shares the check.
  std::vector<Eigen::Vector3d> v;
  std::vector<std::vector<int32_t>> f;
  Torus(8, 4, &v, &f);
  IntakeOptions small;
  small.max_faces = 63;
  EXPECT_EQ(BuildMesh(v, f, small).status().code(),
            absl::StatusCode::kResourceExhausted);
}

TEST(MeshIoTest, MissingFileIsNotFound) {
  auto m = LoadMeshFromFile(kDir + "good/no_such_file.off", {});
  EXPECT_EQ(m.status().code(), absl::StatusCode::kNotFound);
}

struct BadCase {
  std::string file;
  absl::StatusCode code;
  std::string substring;
};

class BadFileTest : public ::testing::TestWithParam<BadCase> {};

TEST_P(BadFileTest, FailsWithExactCodeAndMessage) {
  const BadCase& c = GetParam();
  auto from_file = LoadMeshFromFile(kDir + "bad/" + c.file, {});
  EXPECT_EQ(from_file.status().code(), c.code) << from_file.status();
  EXPECT_THAT(std::string(from_file.status().message()),
              HasSubstr(c.substring));
  // The same bytes as a buffer, format from the name, fail the same way.
  auto from_buffer = LoadMeshFromBuffer(ReadBytes(kDir + "bad/" + c.file),
                                        MeshFormat::kUnknown, c.file, {});
  EXPECT_EQ(from_buffer.status(), from_file.status());
}

INSTANTIATE_TEST_SUITE_P(
    Corpus, BadFileTest,
    ::testing::Values(
        BadCase{
            "truncated.off", absl::StatusCode::kInvalidArgument,
            "OFF: truncated: header declares 4 faces, the file ends after 2"},
        BadCase{
            "wrong_counts.off", absl::StatusCode::kInvalidArgument,
            "OFF: truncated: header declares 4 faces, the file ends after 3"},
        BadCase{"nan.off", absl::StatusCode::kInvalidArgument,
                "OFF line 5: vertex 2 has a non-finite coordinate 'nan'"},
        BadCase{
            "index_out_of_range.obj", absl::StatusCode::kInvalidArgument,
            "OBJ line 9: face 3 references vertex 9 (1-based); the file has "
            "4 vertices"},
        BadCase{"empty.off", absl::StatusCode::kInvalidArgument,
                "OFF: the file is empty"},
        BadCase{"no_faces.off", absl::StatusCode::kInvalidArgument,
                "mesh has no faces"},
        BadCase{"face_two_vertices.off", absl::StatusCode::kInvalidArgument,
                "OFF line 10: face 3 has 2 vertices; at least 3 are needed"},
        BadCase{"garbage.off", absl::StatusCode::kInvalidArgument,
                "OFF line 1: binary data in a text file"},
        BadCase{"garbage.obj", absl::StatusCode::kInvalidArgument,
                "binary data in a text file"},
        BadCase{"garbage.ply", absl::StatusCode::kInvalidArgument,
                "PLY: the file does not start with 'ply'"},
        BadCase{"garbage.stl", absl::StatusCode::kInvalidArgument,
                "but the file has 997 bytes"},
        BadCase{"huge_count_binary.ply", absl::StatusCode::kInvalidArgument,
                "header declares 1000000000000 'vertex' elements"},
        BadCase{"huge_count.stl", absl::StatusCode::kInvalidArgument,
                "header declares 4294967295 triangles"},
        BadCase{"huge_count.off", absl::StatusCode::kInvalidArgument,
                "header declares 1000000000000 vertices"},
        BadCase{"truncated_binary.ply", absl::StatusCode::kInvalidArgument,
                "PLY: truncated in face"},
        BadCase{"truncated_ascii.stl", absl::StatusCode::kInvalidArgument,
                "STL (ASCII): truncated inside triangle 1"},
        BadCase{
            "nan_binary.stl", absl::StatusCode::kInvalidArgument,
            "STL (binary): triangle 0 corner 1 has a non-finite coordinate"}),
    [](const ::testing::TestParamInfo<BadCase>& info) {
      std::string name = info.param.file;
      for (char& c : name) {
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
      }
      return name;
    });

// Robustness: truncations, byte flips and random bytes of every good file
// must yield OK or INVALID_ARGUMENT/RESOURCE_EXHAUSTED, never a crash, a hang
// or an INTERNAL disagreement between the scan and OpenMesh.
TEST(MeshIoTest, MutatedFilesNeverCrashOrDisagree) {
  std::mt19937 rng(20070601);
  const std::vector<std::string> files = {
      "tetrahedron.off",       "cube_quads.obj",     "hex_prism_ngons.obj",
      "cube_ascii.ply",        "cube_binary_le.ply", "cube_binary_be.ply",
      "tetrahedron_ascii.stl", "cube_binary.stl"};
  int failures = 0, loads = 0;
  for (const std::string& f : files) {
    const std::string bytes = ReadBytes(kDir + "good/" + f);
    for (int trial = 0; trial < 150; ++trial) {
      std::string mutated = bytes;
      if (trial < 50) {
        mutated.resize(rng() % bytes.size());
      } else {
        const int flips = 1 + rng() % 4;
        for (int k = 0; k < flips; ++k) {
          mutated[rng() % mutated.size()] = static_cast<char>(rng() % 256);
        }
      }
      auto m = LoadMeshFromBuffer(mutated, MeshFormat::kUnknown, f, {});
      if (m.ok()) {
        ++loads;
        EXPECT_NEAR(m->stats.area, BruteForceArea(m->mesh), 1e-6);
      } else {
        ++failures;
        EXPECT_TRUE(m.status().code() == absl::StatusCode::kInvalidArgument ||
                    m.status().code() == absl::StatusCode::kResourceExhausted)
            << f << " trial " << trial << ": " << m.status();
      }
    }
  }
  EXPECT_GT(failures, 0);
  EXPECT_GT(loads, 0);
}

TEST(MeshIoTest, UnknownFormatIsInvalidArgument) {
  auto m = LoadMeshFromBuffer("hello world", MeshFormat::kUnknown, "x.txt", {});
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(m.status().message(), HasSubstr("cannot tell the mesh format"));
}

// Huge coordinates were reported as "degenerate triangles".
TEST(MeshIoTest, HugeCoordinatesNameTheVertexAndLine) {
  const std::string off =
      "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1e20 0\n0 0 1\n"
      "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  auto m = LoadMeshFromBuffer(off, MeshFormat::kOff, "", {});
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(m.status().message(),
              HasSubstr("OFF line 5: vertex 2: coordinate '1e20' exceeds the "
                        "supported magnitude 1e+15"));
  // Binary formats name the element.
  std::string stl(84 + 50, '\0');
  stl[80] = 1;
  const float huge = 3e30f;
  std::memcpy(&stl[84 + 12 + 12 + 4], &huge, 4);  // corner 1, y
  m = LoadMeshFromBuffer(stl, MeshFormat::kStl, "", {});
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(m.status().message(),
              HasSubstr("STL (binary): triangle 0 corner 1: coordinate 3e+30 "
                        "exceeds the supported magnitude"));
  // BuildMesh too (double coordinates).
  m = BuildMesh({{0, 0, 0}, {1e300, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}, {});
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(m.status().message(),
              HasSubstr("vertex 1: coordinate 1e+300 exceeds"));
  // Within the bound but far from the origin, a unit tetrahedron collapses
  // at float precision: the error says why, not only "degenerate".
  const std::string far =
      "OFF\n4 4 0\n1e12 1e12 1e12\n1000000000001 1e12 1e12\n"
      "1e12 1000000000001 1e12\n1e12 1e12 1000000000001\n"
      "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  m = LoadMeshFromBuffer(far, MeshFormat::kOff, "", {});
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(m.status().message(), HasSubstr("degenerate"));
  EXPECT_THAT(m.status().message(),
              HasSubstr("the coordinates reach 1e+12 but span only"));
}

// Fuzz finding (tests/fuzz/findings/README.md, fuzz_mesh_obj): a sign
// after '+' ("+-0.866") was read as a negative number although strtod, and
// every other reader, refuses it; the scanner dropped the '+' and handed
// "-0.866" to std::from_chars. Every number a text reader parses (OBJ and
// OFF coordinates, face indices and counts, PLY values) refuses it now and
// names the line; a single leading '+' is still a sign.
TEST(MeshIoTest, PlusFollowedByASignIsNotANumber) {
  const std::string tetra_obj =
      "# tetrahedron\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 +1\n"
      "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  auto m = LoadMeshFromBuffer(tetra_obj, MeshFormat::kObj, "", {});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->mesh.positions.size(), 4u);
  struct Case {
    MeshFormat format;
    std::string bytes;
    std::string message;
  };
  const Case cases[] = {
      // The fuzzer's input, cut to the line at fault.
      {MeshFormat::kObj,
       "# tetrahedron\nv 0 0 0\nv -0.5000000000000004 +-0.8660254037844384 "
       "0.0\n"
       "v 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
       "OBJ line 3: vertex 1: expected a coordinate, got "
       "'+-0.8660254037844384'"},
      {MeshFormat::kObj,
       "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
       "f 1 3 2\nf 1 2 4\nf 1 4 +-1\nf 2 3 4\n",
       "OBJ line 7: face 2: expected a vertex index (1-based), got '+-1'"},
      {MeshFormat::kOff,
       "OFF\n4 4 0\n0 0 0\n1 0 0\n0 +-1 0\n0 0 1\n"
       "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
       "OFF line 5: vertex 2: expected a coordinate, got '+-1'"},
      {MeshFormat::kOff,
       "OFF\n+-4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
       "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
       "OFF line 2"},
      {MeshFormat::kPly,
       "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n"
       "property float y\nproperty float z\nelement face 4\n"
       "property list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 +-2\n3 1 2 3\n",
       "PLY line 16"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.bytes);
    m = LoadMeshFromBuffer(c.bytes, c.format, "", {});
    EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument)
        << m.status();
    EXPECT_THAT(m.status().message(), HasSubstr(c.message));
  }
}

TEST(ComputeMeshStatsTest, SingleTriangle) {
  Mesh mesh;
  mesh.positions = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}};
  mesh.triangles = {{0, 1, 2}};
  MeshStats s = ComputeMeshStats(mesh);
  EXPECT_EQ(s.vertices, 3);
  EXPECT_EQ(s.faces, 1);
  EXPECT_DOUBLE_EQ(s.area, 2.0);
  EXPECT_EQ(s.boundary_edges, 3);
  EXPECT_EQ(s.components, 1);
  EXPECT_EQ(s.genus, 0);  // (2 - 3 + 3 - 1 - 1) / 2
}

}  // namespace
}  // namespace tpr::extract
