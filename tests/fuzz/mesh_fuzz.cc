// libFuzzer target: mesh intake of one format (TPR_FUZZ_MESH_FORMAT, set by
// tests/fuzz/CMakeLists.txt: kOff, kObj, kPly or kStl) from a byte buffer.
//
// Oracle: intake either refuses with INVALID_ARGUMENT / RESOURCE_EXHAUSTED
// and a non-empty message, or returns a mesh that keeps every guarantee
// extractor/lib/mesh.h states (finite coordinates, indices in range, no
// repeated vertex in a triangle, no duplicate triangle, each directed edge
// at most once: at most two triangles per edge with consistent orientation,
// every vertex referenced) and whose stats count what it holds. Crashes,
// sanitizer reports, hangs and other status codes are findings.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <set>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "extractor/lib/mesh_io.h"
#include "tests/fuzz/fuzz_check.h"

namespace {

using tpr::extract::LoadedMesh;
using tpr::extract::Mesh;

void CheckMesh(const LoadedMesh& loaded) {
  const Mesh& mesh = loaded.mesh;
  const size_t n = mesh.positions.size();
  FUZZ_CHECK(n > 0 && !mesh.triangles.empty(), "an accepted mesh is not empty");
  for (const auto& p : mesh.positions) {
    FUZZ_CHECK(
        std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()),
        "coordinates are finite");
  }
  std::vector<bool> referenced(n, false);
  std::set<std::array<int32_t, 3>> seen_triangles;
  std::set<std::pair<int32_t, int32_t>> directed_edges;
  for (const auto& t : mesh.triangles) {
    for (int32_t v : t) {
      FUZZ_CHECK(v >= 0 && static_cast<size_t>(v) < n,
                 "triangle index in range");
      referenced[static_cast<size_t>(v)] = true;
    }
    FUZZ_CHECK(t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
               "no repeated vertex in a triangle");
    std::array<int32_t, 3> key = t;
    std::sort(key.begin(), key.end());
    FUZZ_CHECK(seen_triangles.insert(key).second, "no duplicate triangle");
    for (int e = 0; e < 3; ++e) {
      FUZZ_CHECK(directed_edges.insert({t[e], t[(e + 1) % 3]}).second,
                 "each directed edge once (manifold, consistently oriented)");
    }
  }
  FUZZ_CHECK(std::all_of(referenced.begin(), referenced.end(),
                         [](bool b) { return b; }),
             "every vertex referenced");
  FUZZ_CHECK(loaded.stats.vertices == static_cast<int64_t>(n),
             "stats.vertices");
  FUZZ_CHECK(loaded.stats.faces == static_cast<int64_t>(mesh.triangles.size()),
             "stats.faces");
  FUZZ_CHECK(std::isfinite(loaded.stats.area) && loaded.stats.area >= 0,
             "stats.area");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tpr::extract::IntakeOptions options;
  // Small limits keep each run fast; the limit checks are exercised too.
  options.max_vertices = 100'000;
  options.max_faces = 200'000;
  const absl::string_view bytes(reinterpret_cast<const char*>(data), size);
  absl::StatusOr<LoadedMesh> loaded = tpr::extract::LoadMeshFromBuffer(
      bytes, tpr::extract::MeshFormat::TPR_FUZZ_MESH_FORMAT, "", options);
  if (!loaded.ok()) {
    tpr::fuzz::CheckRefusal(loaded.status(),
                            {absl::StatusCode::kInvalidArgument,
                             absl::StatusCode::kResourceExhausted});
    return 0;
  }
  CheckMesh(*loaded);
  return 0;
}
