// Meshes built in code for the geodesic and TPR tests and benchmarks:
// icospheres, surfaces of revolution (capsule, dumbbell, open tube), and
// the disjoint union of two meshes. Header-only so every test binary and
// bench can include it.
//
//   tpr::extract::Mesh s = tpr::testing::Icosphere(3);        // 642 vertices
//   tpr::extract::Mesh d = tpr::testing::Dumbbell(1.0, 0.3, 1.5, 48, 60);
//   tpr::extract::Mesh u = tpr::testing::Union(s, d);
#ifndef TPR_TESTS_EXTRACTOR_TEST_MESHES_H_
#define TPR_TESTS_EXTRACTOR_TEST_MESHES_H_

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <utility>
#include <vector>

#include "extractor/lib/mesh.h"

namespace tpr::testing {

using ::tpr::extract::Mesh;

// Icosphere returns a unit-radius (times `radius`) icosahedron subdivided
// `level` times, vertices projected to the sphere: 10 * 4^level + 2 vertices.
inline Mesh Icosphere(int level, double radius = 1.0) {
  Mesh m;
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  const double base[12][3] = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                              {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                              {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (const auto& b : base) {
    m.positions.push_back(Eigen::Vector3d(b[0], b[1], b[2]).normalized());
  }
  m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                 {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                 {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                 {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < level; ++l) {
    std::map<std::pair<int32_t, int32_t>, int32_t> mid;
    auto midpoint = [&](int32_t a, int32_t b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      const int32_t id = static_cast<int32_t>(m.positions.size());
      m.positions.push_back((m.positions[a] + m.positions[b]).normalized());
      mid.emplace(key, id);
      return id;
    };
    std::vector<std::array<int32_t, 3>> next;
    next.reserve(m.triangles.size() * 4);
    for (const auto& tri : m.triangles) {
      const int32_t a = midpoint(tri[0], tri[1]);
      const int32_t b = midpoint(tri[1], tri[2]);
      const int32_t c = midpoint(tri[2], tri[0]);
      next.push_back({tri[0], a, c});
      next.push_back({tri[1], b, a});
      next.push_back({tri[2], c, b});
      next.push_back({a, b, c});
    }
    m.triangles = std::move(next);
  }
  for (auto& p : m.positions) p *= radius;
  return m;
}

// IcosphereLevelForVertices returns the smallest level with at least n
// vertices.
inline int IcosphereLevelForVertices(int64_t n) {
  int level = 0;
  while (10 * (int64_t{1} << (2 * level)) + 2 < n) ++level;
  return level;
}

// Revolution returns the surface of revolution about the z axis of the
// profile curve `profile(s) = (radius, z)`, s in [0, 1], resampled to
// `rings` + 1 points equally spaced in arc length. When the profile's radius
// is 0 at an end, that end is a pole vertex (closed surface); otherwise the
// end ring is a boundary. Each ring has `around` vertices, rotated half a
// step from the previous ring so that triangles are near equilateral.
inline Mesh Revolution(const std::function<Eigen::Vector2d(double)>& profile,
                       int rings, int around) {
  // Dense polyline, then equal arc-length resampling.
  const int dense = 4000;
  std::vector<Eigen::Vector2d> pts(dense + 1);
  std::vector<double> acc(dense + 1, 0.0);
  for (int i = 0; i <= dense; ++i) {
    pts[i] = profile(static_cast<double>(i) / dense);
    if (i > 0) acc[i] = acc[i - 1] + (pts[i] - pts[i - 1]).norm();
  }
  std::vector<Eigen::Vector2d> samples(rings + 1);
  for (int r = 0; r <= rings; ++r) {
    const double target = acc[dense] * r / rings;
    const int j = static_cast<int>(
        std::lower_bound(acc.begin(), acc.end(), target) - acc.begin());
    if (j == 0) {
      samples[r] = pts[0];
    } else {
      const double w =
          (target - acc[j - 1]) / std::max(1e-300, acc[j] - acc[j - 1]);
      samples[r] = pts[j - 1] + w * (pts[j] - pts[j - 1]);
    }
  }
  const double kPi = 3.14159265358979323846;
  Mesh m;
  std::vector<int32_t> ring_start(rings + 1, -1);  // -1 for a pole ring
  std::vector<int32_t> pole(rings + 1, -1);
  for (int r = 0; r <= rings; ++r) {
    const double rad = samples[r].x();
    const double z = samples[r].y();
    if ((r == 0 || r == rings) && rad <= 1e-12) {
      pole[r] = static_cast<int32_t>(m.positions.size());
      m.positions.emplace_back(0.0, 0.0, z);
      continue;
    }
    ring_start[r] = static_cast<int32_t>(m.positions.size());
    for (int k = 0; k < around; ++k) {
      const double a = 2.0 * kPi * (k + 0.5 * (r % 2)) / around;
      m.positions.emplace_back(rad * std::cos(a), rad * std::sin(a), z);
    }
  }
  // Orientation: z decreases... whichever; tests do not depend on it, but
  // keep it consistent across the whole surface.
  for (int r = 0; r < rings; ++r) {
    const bool top_pole = pole[r] >= 0;
    const bool bottom_pole = pole[r + 1] >= 0;
    for (int k = 0; k < around; ++k) {
      const int k1 = (k + 1) % around;
      if (top_pole) {
        m.triangles.push_back(
            {pole[r], ring_start[r + 1] + k1, ring_start[r + 1] + k});
      } else if (bottom_pole) {
        m.triangles.push_back(
            {ring_start[r] + k, ring_start[r] + k1, pole[r + 1]});
      } else {
        const int32_t a = ring_start[r] + k;
        const int32_t b = ring_start[r] + k1;
        const int32_t c = ring_start[r + 1] + k;
        const int32_t d = ring_start[r + 1] + k1;
        if (r % 2 == 0) {
          // Ring r+1 is rotated +half a step: c sits between a and b.
          m.triangles.push_back({a, b, c});
          m.triangles.push_back({b, d, c});
        } else {
          // Ring r+1 is rotated back: b sits between c and d.
          m.triangles.push_back({a, d, c});
          m.triangles.push_back({a, b, d});
        }
      }
    }
  }
  return m;
}

// Capsule returns a closed capsule along z: a cylinder of `radius` and
// length `length` between two hemispherical caps. The tips are at
// z = +-(length / 2 + radius).
inline Mesh Capsule(double radius, double length, int rings, int around) {
  const double kPi = 3.14159265358979323846;
  const double cap = 0.5 * kPi * radius;
  const double total = 2.0 * cap + length;
  return Revolution(
      [=](double s) {
        const double a = s * total;  // arc length from the top tip
        if (a < cap) {
          const double phi = a / radius;
          return Eigen::Vector2d(radius * std::sin(phi),
                                 0.5 * length + radius * std::cos(phi));
        }
        if (a <= cap + length) {
          return Eigen::Vector2d(radius, 0.5 * length - (a - cap));
        }
        const double phi = (a - cap - length) / radius;
        return Eigen::Vector2d(radius * std::cos(phi),
                               -0.5 * length - radius * std::sin(phi));
      },
      rings, around);
}

// Dumbbell returns two balls of radius `ball_top` (centre z = +half) and
// `ball_bottom` (centre z = -half) joined by a neck of radius `neck`. With
// equal balls it is symmetric about z = 0, where G is smallest.
inline Mesh Dumbbell(double ball_top, double ball_bottom, double neck,
                     double half, int rings, int around) {
  const double top = half + ball_top;
  const double bottom = -half - ball_bottom;
  return Revolution(
      [=](double s) {
        const double z = top - s * (top - bottom);
        double r = neck;
        const double dt = z - half;
        const double db = z + half;
        if (std::abs(dt) < ball_top) {
          r = std::max(r, std::sqrt(ball_top * ball_top - dt * dt));
        }
        if (std::abs(db) < ball_bottom) {
          r = std::max(r, std::sqrt(ball_bottom * ball_bottom - db * db));
        }
        if (s <= 0.0 || s >= 1.0) r = 0.0;
        return Eigen::Vector2d(r, z);
      },
      rings, around);
}

// Tube returns an open cylinder of `radius` from z = 0 to z = `length`
// (two boundary loops).
inline Mesh Tube(double radius, double length, int rings, int around) {
  return Revolution(
      [=](double s) { return Eigen::Vector2d(radius, s * length); }, rings,
      around);
}

// Rectangle returns the flat rectangle [0, a] x [0, b] in the z = 0 plane
// as an nx by ny grid of cells, each split into two triangles along
// alternating diagonals (so the mesh has no preferred direction); the
// outline is its boundary.
inline Mesh Rectangle(double a, double b, int nx, int ny) {
  Mesh m;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i)
      m.positions.emplace_back(a * i / nx, b * j / ny, 0.0);
  }
  auto id = [nx](int i, int j) {
    return static_cast<int32_t>(j * (nx + 1) + i);
  };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int32_t p = id(i, j), q = id(i + 1, j), r = id(i + 1, j + 1),
                    s = id(i, j + 1);
      if ((i + j) % 2 == 0) {
        m.triangles.push_back({p, q, r});
        m.triangles.push_back({p, r, s});
      } else {
        m.triangles.push_back({p, q, s});
        m.triangles.push_back({q, r, s});
      }
    }
  }
  return m;
}

// Union returns a and b as one mesh of two components (b's ids shifted).
inline Mesh Union(const Mesh& a, const Mesh& b) {
  Mesh m = a;
  const int32_t shift = static_cast<int32_t>(a.positions.size());
  m.positions.insert(m.positions.end(), b.positions.begin(), b.positions.end());
  for (const auto& t : b.triangles) {
    m.triangles.push_back({t[0] + shift, t[1] + shift, t[2] + shift});
  }
  return m;
}

}  // namespace tpr::testing

#endif  // TPR_TESTS_EXTRACTOR_TEST_MESHES_H_
