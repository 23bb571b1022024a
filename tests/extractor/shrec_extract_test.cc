// Extracts every SHREC'07 watertight mesh listed in
// $TPR_SHARED_DIR/data/shrec07-watertight/MANIFEST.txt ("<path> <class>" per
// line) and prints per-class average point and ring counts. Skipped when the
// data is absent. Slow (a few hundred meshes), hence its own binary.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "gtest/gtest.h"

namespace tpr::extract {
namespace {

TEST(ShrecExtractTest, EveryMeshExtractsOrFailsClearly) {
  const std::string dir =
      std::string(TPR_SHARED_DIR) + "/data/shrec07-watertight";
  std::ifstream manifest(dir + "/MANIFEST.txt");
  if (!manifest) GTEST_SKIP() << "no " << dir << "/MANIFEST.txt";
  struct Tally {
    int meshes = 0, points = 0, rings = 0, warned = 0;
    double ms = 0.0;
  };
  std::map<std::string, Tally> per_class;
  std::string line;
  int total = 0, failed = 0;
  while (std::getline(manifest, line)) {
    std::istringstream in(line);
    std::string path, cls;
    if (!(in >> path >> cls)) continue;
    ++total;
    absl::StatusOr<LoadedMesh> mesh =
        LoadMeshFromFile(dir + "/" + path, IntakeOptions{});
    if (!mesh.ok()) {
      // Intake refuses with a clear INVALID_ARGUMENT (e.g. non-manifold).
      EXPECT_EQ(mesh.status().code(), absl::StatusCode::kInvalidArgument)
          << path;
      EXPECT_FALSE(mesh.status().message().empty());
      ++failed;
      std::printf("intake %s: %s\n", path.c_str(),
                  std::string(mesh.status().message()).c_str());
      continue;
    }
    absl::StatusOr<ExtractResult> r =
        ExtractSignature(mesh->mesh, mesh->stats, Options{});
    ASSERT_TRUE(r.ok()) << path << ": " << r.status();
    Tally& t = per_class[cls];
    ++t.meshes;
    double sum = 0.0;
    for (const Feature& f : r->signature.features) {
      (f.kind == FeatureKind::kPoint ? t.points : t.rings) += 1;
      sum += f.weight;
      EXPECT_GE(f.weight, 0.0) << path;
      for (double x : f.curvature) EXPECT_TRUE(std::isfinite(x)) << path;
      for (double x : f.area) EXPECT_TRUE(std::isfinite(x)) << path;
      for (double x : f.distance) EXPECT_TRUE(std::isfinite(x)) << path;
    }
    EXPECT_NEAR(sum, 1.0, 1e-9) << path;
    t.warned += !r->warnings.empty();
    for (const StageTiming& s : r->timings) t.ms += s.milliseconds;
  }
  std::printf("%-12s %6s %8s %8s %7s %9s\n", "class", "meshes", "points",
              "rings", "warned", "ms/mesh");
  for (const auto& [cls, t] : per_class) {
    std::printf("%-12s %6d %8.2f %8.2f %7d %9.1f\n", cls.c_str(), t.meshes,
                static_cast<double>(t.points) / t.meshes,
                static_cast<double>(t.rings) / t.meshes, t.warned,
                t.ms / t.meshes);
  }
  std::printf("total %d, refused by intake %d\n", total, failed);
  EXPECT_GT(total, 0);
}

}  // namespace
}  // namespace tpr::extract
