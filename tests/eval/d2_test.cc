#include "eval/lib/d2.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <utility>

#include "eval/lib/plots.h"

namespace tpr::eval {
namespace {

// Unit icosphere: an icosahedron subdivided `levels` times, projected.
extract::Mesh Icosphere(int levels) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  extract::Mesh m;
  m.positions = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                 {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                 {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                 {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                 {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                 {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.positions.push_back((m.positions[a] + m.positions[b]) / 2);
      return mid[key] = static_cast<int>(m.positions.size()) - 1;
    };
    std::vector<std::array<int32_t, 3>> next;
    for (const auto& f : m.triangles) {
      const int a = midpoint(f[0], f[1]), b = midpoint(f[1], f[2]),
                c = midpoint(f[2], f[0]);
      next.push_back({f[0], a, c});
      next.push_back({f[1], b, a});
      next.push_back({f[2], c, b});
      next.push_back({a, b, c});
    }
    m.triangles = std::move(next);
  }
  for (auto& p : m.positions) p.normalize();
  return m;
}

TEST(D2Test, SphereMatchesTheAnalyticDistribution) {
  // On a unit sphere the chord length d of two uniform points has density
  // d / 2 on [0, 2] and mean 4/3, so P(a <= d < b) = (b^2 - a^2) / 4.
  D2Options options;
  options.pairs = 1 << 18;
  const std::vector<double> h = D2Histogram(Icosphere(5), options);
  ASSERT_EQ(h.size(), 64u);
  const double mean = 4.0 / 3.0, width = options.range * mean / options.bins;
  double total = 0.0;
  for (int b = 0; b < options.bins; ++b) {
    const double lo = std::min(2.0, b * width),
                 hi = std::min(2.0, (b + 1) * width);
    EXPECT_NEAR(h[b], (hi * hi - lo * lo) / 4.0, 0.004) << "bin " << b;
    total += h[b];
  }
  EXPECT_NEAR(total, 1.0, 1e-9);
}

TEST(D2Test, InvariantToRigidMotionAndScale) {
  extract::Mesh a = Icosphere(3);
  for (auto& p : a.positions) p.x() *= 2.0;  // an ellipsoid
  extract::Mesh b = a;
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized())
          .toRotationMatrix();
  for (auto& p : b.positions) p = 1.7 * (r * p) + Eigen::Vector3d(5, -2, 1);
  D2Options options;
  options.pairs = 1 << 18;
  const double same =
      D2Distance(D2Histogram(a, options), D2Histogram(b, options));
  const double sphere =
      D2Distance(D2Histogram(a, options), D2Histogram(Icosphere(3), options));
  EXPECT_LT(same, 0.03);
  EXPECT_GT(sphere, 5 * same);
}

TEST(D2Test, SameSeedSameHistogramAndEmptyMeshIsEmpty) {
  D2Options options;
  options.pairs = 4096;
  EXPECT_EQ(D2Histogram(Icosphere(1), options),
            D2Histogram(Icosphere(1), options));
  EXPECT_TRUE(D2Histogram(extract::Mesh{}, options).empty());
}

TEST(PlotsTest, SvgsAreWellFormedAndNameEverySeries) {
  Curve c{"TPR <ours>", {}};
  for (int i = 0; i < kRecallLevels; ++i) c.precision[i] = 1.0 - i / 40.0;
  const std::string pr = PrecisionRecallSvg({c, {"D2", {}}}, "PR");
  EXPECT_EQ(pr.rfind("<svg", 0), 0u);
  EXPECT_NE(pr.find("TPR &lt;ours&gt;"), std::string::npos);
  EXPECT_NE(pr.find("</svg>"), std::string::npos);
  SimilarityMatrix m{{"a", "b"}, {{0, 1}, {1, 0}}, {{1, 0}, {0, 1}}};
  const std::string sm = SimilaritySvg(m, "similarity");
  EXPECT_NE(sm.find("rgb(0,0,0)"), std::string::npos);        // similarity 1
  EXPECT_NE(sm.find("rgb(255,255,255)"), std::string::npos);  // similarity 0
}

}  // namespace
}  // namespace tpr::eval
