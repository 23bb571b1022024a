// Pose stability of TPR analysis on a real registered body: the SCAPE
// person ($TPR_SHARED_DIR/data/scape/, 71 poses, vertex ids corresponding
// across poses). Skipped when the data is absent. Slow (tens of
// extractions at 12,500 vertices), hence its own binary.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "gtest/gtest.h"

namespace tpr::extract {
namespace {

std::string ScapeDir() {
  const char* env = std::getenv("TPR_SHARED_DIR");
  return std::string(env != nullptr ? env : TPR_SHARED_DIR) + "/data/scape";
}

// Counted is what one pose gives under one method.
struct Counted {
  int points = 0, rings = 0;
  std::vector<int32_t> point_vertices;
};

Counted Count(const LoadedMesh& mesh, TopologyMethod method) {
  Options options;
  options.topology = method;
  options.spectrum_eigenvalues = 0;
  options.explain = true;
  absl::StatusOr<ExtractResult> r =
      ExtractSignature(mesh.mesh, mesh.stats, options);
  EXPECT_TRUE(r.ok()) << r.status();
  Counted c;
  if (!r.ok()) return c;
  for (size_t i = 0; i < r->signature.features.size(); ++i) {
    if (r->signature.features[i].kind == FeatureKind::kPoint) {
      ++c.points;
      c.point_vertices.push_back(r->explanation->feature_vertices[i][0]);
    } else {
      ++c.rings;
    }
  }
  return c;
}

int Spread(const std::vector<Counted>& counts, int Counted::*field) {
  int lo = counts.front().*field, hi = lo;
  for (const Counted& c : counts) {
    lo = std::min(lo, c.*field);
    hi = std::max(hi, c.*field);
  }
  return hi - lo;
}

// Every third pose under both methods. The persistence method must at
// least halve the paper's spread of point and ring counts (measured on the
// same poses), find one point per limb tip (head, two hands, two feet),
// and find the same five in every pose: through the vertex correspondence,
// each pose's points sit, on the rest pose (mesh000), within 0.25 (the
// body is 1.85 tall) of the rest pose's own points, one each.
TEST(ScapeStabilityTest, PersistenceHalvesTheCountSpreadAndKeepsTheLimbs) {
  const std::string dir = ScapeDir();
  std::ifstream manifest(dir + "/MANIFEST.txt");
  if (!manifest) GTEST_SKIP() << "no " << dir << "/MANIFEST.txt";
  std::vector<std::string> files;
  std::string line;
  while (std::getline(manifest, line)) {
    std::istringstream in(line);
    std::string path;
    if (in >> path) files.push_back(dir + "/" + path);
  }
  ASSERT_GE(files.size(), 30u);
  absl::StatusOr<LoadedMesh> rest = LoadMeshFromFile(files[0], {});
  ASSERT_TRUE(rest.ok()) << rest.status();
  std::vector<Counted> paper, persistence;
  for (size_t i = 0; i < files.size(); i += 3) {
    absl::StatusOr<LoadedMesh> mesh = LoadMeshFromFile(files[i], {});
    ASSERT_TRUE(mesh.ok()) << files[i] << ": " << mesh.status();
    ASSERT_EQ(mesh->mesh.positions.size(), rest->mesh.positions.size());
    paper.push_back(Count(*mesh, TopologyMethod::kPaper));
    persistence.push_back(Count(*mesh, TopologyMethod::kPersistence));
  }
  const int paper_points = Spread(paper, &Counted::points);
  const int paper_rings = Spread(paper, &Counted::rings);
  const int points = Spread(persistence, &Counted::points);
  const int rings = Spread(persistence, &Counted::rings);
  std::printf(
      "%zu poses: spread of points %d (paper %d), rings %d (paper %d)\n",
      paper.size(), points, paper_points, rings, paper_rings);
  EXPECT_LE(2 * points, paper_points);
  EXPECT_LE(2 * rings, paper_rings);

  const std::vector<Eigen::Vector3d>& at = rest->mesh.positions;
  const std::vector<int32_t>& reference = persistence.front().point_vertices;
  ASSERT_EQ(reference.size(), 5u);
  for (size_t a = 0; a < reference.size(); ++a) {
    for (size_t b = a + 1; b < reference.size(); ++b) {
      EXPECT_GT((at[reference[a]] - at[reference[b]]).norm(), 0.3);
    }
  }
  for (size_t pose = 0; pose < persistence.size(); ++pose) {
    const std::vector<int32_t>& p = persistence[pose].point_vertices;
    EXPECT_EQ(p.size(), 5u) << "pose " << 3 * pose;
    std::vector<int> matched(reference.size(), 0);
    for (int32_t v : p) {
      size_t best = 0;
      for (size_t r = 1; r < reference.size(); ++r) {
        if ((at[v] - at[reference[r]]).norm() <
            (at[v] - at[reference[best]]).norm())
          best = r;
      }
      EXPECT_LT((at[v] - at[reference[best]]).norm(), 0.25)
          << "pose " << 3 * pose << " vertex " << v;
      ++matched[best];
    }
    for (int m : matched) EXPECT_EQ(m, 1) << "pose " << 3 * pose;
  }
}

}  // namespace
}  // namespace tpr::extract
