// Tests for the Laplace-Beltrami spectrum (extractor/lib/spectrum.h).
//
// Oracles: the analytic spectra of the unit sphere (l (l + 1), multiplicity
// 2 l + 1) and of a flat rectangle with free (Neumann) boundary
// (pi^2 (m^2 / a^2 + n^2 / b^2)); invariance under similarity (exact up to
// rounding); and the same shape meshed or simplified differently (looser,
// the tolerance measured and stated).
#include "extractor/lib/spectrum.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "extractor/synth/synth.h"
#include "gtest/gtest.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extract {
namespace {

constexpr double kPi = 3.14159265358979323846;

// SphereSpectrum: l (l + 1) with multiplicity 2 l + 1, l >= 1, first n.
std::vector<double> SphereSpectrum(int n) {
  std::vector<double> out;
  for (int l = 1; static_cast<int>(out.size()) < n; ++l) {
    for (int k = 0; k < 2 * l + 1 && static_cast<int>(out.size()) < n; ++k) {
      out.push_back(l * (l + 1.0));
    }
  }
  return out;
}

// RectangleSpectrum: the Neumann eigenvalues of [0, a] x [0, b] except the
// zero one, times the area / (4 pi), first n in ascending order.
std::vector<double> RectangleSpectrum(double a, double b, int n) {
  std::vector<double> all;
  for (int m = 0; m < 40; ++m) {
    for (int k = 0; k < 40; ++k) {
      if (m == 0 && k == 0) continue;
      all.push_back(kPi * kPi * (m * m / (a * a) + k * k / (b * b)) * a * b /
                    (4.0 * kPi));
    }
  }
  std::sort(all.begin(), all.end());
  all.resize(n);
  return all;
}

double MaxRelativeError(const std::vector<double>& got,
                        const std::vector<double>& want) {
  EXPECT_EQ(got.size(), want.size());
  double worst = 0.0;
  for (size_t i = 0; i < std::min(got.size(), want.size()); ++i) {
    worst = std::max(worst, std::abs(got[i] - want[i]) / want[i]);
  }
  return worst;
}

Mesh Biped(int vertices, int pose = 0) {
  synth::ShapeOptions options;
  options.target_vertices = vertices;
  absl::StatusOr<Mesh> mesh =
      synth::GenerateShape("biped_adult", pose, options);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? *mesh : Mesh{};
}

std::vector<double> Eigenvalues(const Mesh& mesh,
                                const SpectrumOptions& options) {
  absl::StatusOr<Spectrum> s = LaplaceBeltramiSpectrum(mesh, options);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? s->eigenvalues : std::vector<double>{};
}

std::vector<double> Head(const std::vector<double>& v, size_t n) {
  return std::vector<double>(v.begin(), v.begin() + std::min(n, v.size()));
}

Mesh Similarity(const Mesh& mesh, double scale) {
  const Eigen::Matrix3d r =
      (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()) *
       Eigen::AngleAxisd(-1.9, Eigen::Vector3d::UnitZ()))
          .toRotationMatrix();
  Mesh out = mesh;
  for (Eigen::Vector3d& p : out.positions)
    p = scale * (r * p) + Eigen::Vector3d(3.0, -7.5, 0.25);
  return out;
}

// The unit sphere's spectrum is l (l + 1), multiplicity 2 l + 1 (the
// spherical harmonics). Linear FEM converges as h^2: each icosphere level
// halves h, so the worst relative error over l = 1..6 (48 values) must
// shrink about 4x per level. Measured: 6.3% (642 vertices), 1.5% (2562),
// 0.38% (10242).
TEST(SpectrumTest, UnitSphereMatchesAnalyticAndConverges) {
  SpectrumOptions options;
  options.eigenvalues = 48;
  options.max_vertices = 0;
  const double tolerance[] = {0.07, 0.017, 0.0045};
  double previous = 1.0;
  for (int level : {3, 4, 5}) {
    const std::vector<double> got =
        Eigenvalues(testing::Icosphere(level), options);
    const double error = MaxRelativeError(got, SphereSpectrum(48));
    EXPECT_LT(error, tolerance[level - 3]) << "level " << level;
    EXPECT_LT(error, previous / 3.5)
        << "level " << level << " does not converge as h^2";
    previous = error;
  }
}

// The 2 l + 1 copies of each eigenvalue must all be found (Lanczos can
// miss copies of a multiple eigenvalue): the values for one l lie closer
// to l (l + 1) than to any other l's.
TEST(SpectrumTest, UnitSphereKeepsMultiplicities) {
  SpectrumOptions options;
  options.eigenvalues = 48;
  options.max_vertices = 0;
  const std::vector<double> got = Eigenvalues(testing::Icosphere(4), options);
  ASSERT_EQ(got.size(), 48u);
  int i = 0;
  for (int l = 1; l <= 6; ++l) {
    for (int k = 0; k < 2 * l + 1; ++k, ++i) {
      EXPECT_NEAR(got[i], l * (l + 1.0), 0.5 * l) << "value " << i;
    }
  }
}

// A flat rectangle with free boundary: pi^2 (m^2 / a^2 + n^2 / b^2), the
// natural (Neumann) condition of the FEM. The first 30 values, two grid
// resolutions. Measured worst relative error: 1.4% (40 x 60 cells), 0.34%
// (80 x 120), the h^2 rate.
TEST(SpectrumTest, RectangleMatchesNeumannAnalytic) {
  SpectrumOptions options;
  options.eigenvalues = 30;
  options.max_vertices = 0;
  const std::vector<double> want = RectangleSpectrum(1.0, 1.5, 30);
  const double coarse = MaxRelativeError(
      Eigenvalues(testing::Rectangle(1.0, 1.5, 40, 60), options), want);
  const double fine = MaxRelativeError(
      Eigenvalues(testing::Rectangle(1.0, 1.5, 80, 120), options), want);
  EXPECT_LT(coarse, 0.02);
  EXPECT_LT(fine, 0.005);
  EXPECT_LT(fine, coarse / 3.0);
}

// Rotation, translation and uniform scale change no stored value beyond
// rounding: the scaled eigenvalues are similarity invariants.
TEST(SpectrumTest, InvariantUnderRigidMotionAndScale) {
  const Mesh mesh = Biped(2000, /*pose=*/3);
  const std::vector<double> a = Eigenvalues(mesh, SpectrumOptions{});
  for (double scale : {1.0, 0.013, 37.0}) {
    const std::vector<double> b =
        Eigenvalues(Similarity(mesh, scale), SpectrumOptions{});
    EXPECT_LT(MaxRelativeError(b, a), 1e-7) << "scale " << scale;
  }
}

// The same shape at 5k and at 20k vertices (different polygonizations),
// both through the default options (the 20k mesh simplified to
// max_vertices): the spectra agree to 0.26% (measured worst relative
// difference over the default 20 values; 1.3% over 50 when both meshes
// were simplified to 3000).
TEST(SpectrumTest, StableUnderRemeshing) {
  const std::vector<double> a = Eigenvalues(Biped(5000, 2), SpectrumOptions{});
  const std::vector<double> b = Eigenvalues(Biped(20000, 2), SpectrumOptions{});
  const double error = MaxRelativeError(a, b);
  EXPECT_LT(error, 0.01);
}

// The simplification behind SpectrumOptions::max_vertices, eigenvalue by
// eigenvalue: the 20k-vertex biped solved whole, and simplified to the
// default bound and to 3000 vertices. Every one of the default 50 values
// must stay within the stated relative difference of the whole mesh's.
// Measured worst over the 50 values: 0.59% at 12000 vertices, 4.2% at
// 3000 (the higher eigenvalues, of shorter wavelength, move most).
TEST(SpectrumTest, StableUnderSimplification) {
  const Mesh full = Biped(20000, 1);
  SpectrumOptions whole;
  whole.max_vertices = 0;
  const std::vector<double> reference = Eigenvalues(full, whole);
  ASSERT_EQ(reference.size(),
            static_cast<size_t>(SpectrumOptions{}.eigenvalues));
  for (const auto& [bound, tolerance] :
       {std::pair<int, double>{SpectrumOptions{}.max_vertices, 0.0075},
        std::pair<int, double>{12000, 0.0075},
        std::pair<int, double>{3000, 0.05}}) {
    SpectrumOptions simplified;
    simplified.max_vertices = bound;
    absl::StatusOr<Spectrum> s = LaplaceBeltramiSpectrum(full, simplified);
    ASSERT_TRUE(s.ok()) << s.status();
    EXPECT_EQ(s->vertices, bound);
    ASSERT_EQ(s->eigenvalues.size(), reference.size());
    for (size_t i = 0; i < reference.size(); ++i) {
      const double error =
          std::abs(s->eigenvalues[i] - reference[i]) / reference[i];
      EXPECT_LT(error, tolerance)
          << "eigenvalue " << i + 1 << " at " << bound << " vertices";
    }
  }
}

// On the sphere, simplification from 10242 to 3000 vertices keeps the
// analytic spectrum within 2.5% (measured; the 2562-vertex icosphere
// itself is at 1.5%).
TEST(SpectrumTest, SimplifiedSphereStaysNearAnalytic) {
  SpectrumOptions options;
  options.eigenvalues = 48;
  options.max_vertices = 3000;
  absl::StatusOr<Spectrum> s =
      LaplaceBeltramiSpectrum(testing::Icosphere(5), options);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_LE(s->vertices, 3000);
  const double error =
      MaxRelativeError(Head(s->eigenvalues, 48), SphereSpectrum(48));
  EXPECT_LT(error, 0.03);
}

// Two unit spheres: two zero eigenvalues skipped, then each sphere's
// spectrum twice over, scaled by the total area 8 pi: 4 (x6), 12 (x10).
TEST(SpectrumTest, SkipsOneZeroPerComponent) {
  const Mesh two = testing::Union(testing::Icosphere(4),
                                  Similarity(testing::Icosphere(4), 1.0));
  SpectrumOptions options;
  options.eigenvalues = 16;
  absl::StatusOr<Spectrum> s = LaplaceBeltramiSpectrum(two, options);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->components, 2);
  for (int i = 0; i < 16; ++i) {
    EXPECT_NEAR(s->eigenvalues[i], i < 6 ? 4.0 : 12.0, i < 6 ? 0.02 : 0.1) << i;
  }
}

// 12 vertices in one component: 11 non-zero eigenvalues (the dense path);
// 1442 vertices (the iterative path) reach 1440.
TEST(SpectrumTest, TooFewVerticesIsInvalidArgumentUnlessAllowed) {
  const Mesh ico = testing::Icosphere(0);
  SpectrumOptions options;
  options.eigenvalues = 12;
  absl::StatusOr<Spectrum> s = LaplaceBeltramiSpectrum(ico, options);
  ASSERT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("12 vertices"), std::string::npos)
      << s.status();
  EXPECT_NE(s.status().message().find("at most 11"), std::string::npos)
      << s.status();
  options.allow_fewer = true;
  s = LaplaceBeltramiSpectrum(ico, options);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->eigenvalues.size(), 11u);
  // The icosahedron's symmetry keeps the l = 1 triple exact.
  EXPECT_NEAR(s->eigenvalues[0], s->eigenvalues[2], 1e-9 * s->eigenvalues[0]);
  SpectrumOptions iterative;
  iterative.eigenvalues = 1282;
  iterative.max_vertices = 0;
  s = LaplaceBeltramiSpectrum(
      testing::Union(testing::Icosphere(3), testing::Icosphere(3)), iterative);
  ASSERT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.status().message().find("at most 1281"), std::string::npos)
      << s.status();
}

// The dense solver is the iterative one's oracle on the same mesh.
TEST(SpectrumTest, DenseAndIterativeAgree) {
  for (const Mesh& mesh : {Biped(1000, 4), testing::Icosphere(3)}) {
    SpectrumOptions dense, iterative;
    dense.dense_max_vertices = 5000;
    iterative.dense_max_vertices = 0;
    EXPECT_LT(MaxRelativeError(Eigenvalues(mesh, iterative),
                               Eigenvalues(mesh, dense)),
              1e-8);
  }
}

TEST(SpectrumTest, BadInputIsInvalidArgument) {
  EXPECT_EQ(LaplaceBeltramiSpectrum(Mesh{}, SpectrumOptions{}).status().code(),
            absl::StatusCode::kInvalidArgument);
  Mesh flat;
  flat.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  flat.triangles = {{0, 1, 2}, {1, 3, 2}};
  SpectrumOptions one;
  one.eigenvalues = 1;
  EXPECT_EQ(LaplaceBeltramiSpectrum(flat, one).status().code(),
            absl::StatusCode::kInvalidArgument);
  for (auto mutate : {+[](SpectrumOptions& o) { o.eigenvalues = 0; },
                      +[](SpectrumOptions& o) { o.max_vertices = 3; },
                      +[](SpectrumOptions& o) { o.shift = 0.0; },
                      +[](SpectrumOptions& o) { o.tolerance = 0.0; },
                      +[](SpectrumOptions& o) { o.max_restarts = 0; },
                      +[](SpectrumOptions& o) { o.max_lanczos_vectors = -1; },
                      +[](SpectrumOptions& o) { o.dense_max_vertices = -1; }}) {
    SpectrumOptions o;
    mutate(o);
    EXPECT_EQ(LaplaceBeltramiSpectrum(testing::Icosphere(2), o).status().code(),
              absl::StatusCode::kInvalidArgument);
  }
  EXPECT_EQ(SimplifyMesh(testing::Icosphere(2), 3).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// The unrestarted Lanczos iteration (the default) and Spectra's restarted
// one (forced by max_lanczos_vectors = 1, or reached when the unrestarted
// basis is too small to converge) find the same 50 eigenvalues, on a mesh
// without symmetry and on one with multiple eigenvalues; and the operator
// products stay within the documented 3 nev + 20 vectors.
TEST(SpectrumTest, UnrestartedAndRestartedLanczosAgree) {
  const Mesh meshes[] = {Biped(2000, 4), testing::Icosphere(3)};
  for (const Mesh& mesh : meshes) {
    SpectrumOptions plain, restarted, fallback;
    plain.eigenvalues = restarted.eigenvalues = fallback.eigenvalues = 50;
    restarted.max_lanczos_vectors = 1;
    fallback.max_lanczos_vectors = 60;  // > nev = 51, too few to converge
    absl::StatusOr<Spectrum> a = LaplaceBeltramiSpectrum(mesh, plain);
    absl::StatusOr<Spectrum> b = LaplaceBeltramiSpectrum(mesh, restarted);
    absl::StatusOr<Spectrum> c = LaplaceBeltramiSpectrum(mesh, fallback);
    ASSERT_TRUE(a.ok() && b.ok() && c.ok());
    EXPECT_LT(MaxRelativeError(a->eigenvalues, b->eigenvalues), 1e-9);
    EXPECT_LT(MaxRelativeError(c->eigenvalues, b->eigenvalues), 1e-9);
    if (&mesh == &meshes[0]) {
      // One run each (no multiple eigenvalue): the fallback paid for the
      // 60 unrestarted products, then did what the restarted one did.
      EXPECT_EQ(c->operations, b->operations + 60);
      EXPECT_LE(a->operations, 3 * 51 + 20);
    }
  }
}

// Above 200 pairs the default goes straight to the restarted iteration
// (bounded basis): the same products as when forced, and the same values.
TEST(SpectrumTest, ManyEigenvaluesUseTheRestartedIteration) {
  const Mesh mesh = Biped(1000, 2);
  SpectrumOptions many, forced;
  many.eigenvalues = forced.eigenvalues = 210;
  forced.max_lanczos_vectors = 1;
  absl::StatusOr<Spectrum> a = LaplaceBeltramiSpectrum(mesh, many);
  absl::StatusOr<Spectrum> b = LaplaceBeltramiSpectrum(mesh, forced);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->operations, b->operations);
  EXPECT_EQ(a->eigenvalues, b->eigenvalues);
}

// Non-convergence is reported, not hidden: one restart is not enough.
TEST(SpectrumTest, NonConvergenceIsInternal) {
  SpectrumOptions options;
  options.max_lanczos_vectors = 1;  // the restarted iteration
  options.max_restarts = 1;
  options.tolerance = 1e-15;
  absl::StatusOr<Spectrum> s = LaplaceBeltramiSpectrum(Biped(2000), options);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), absl::StatusCode::kInternal);
  EXPECT_NE(s.status().message().find("did not converge"), std::string::npos)
      << s.status();
}

// SimplifyMesh reaches its target on a closed mesh and keeps it closed
// (every edge in two triangles).
TEST(SpectrumTest, SimplifyMeshReachesTargetAndStaysClosed) {
  absl::StatusOr<Mesh> m = SimplifyMesh(testing::Icosphere(5), 2000);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->positions.size(), 2000u);
  std::map<std::pair<int32_t, int32_t>, int> edges;
  for (const auto& t : m->triangles) {
    for (int k = 0; k < 3; ++k) {
      ++edges[std::minmax(t[k], t[(k + 1) % 3])];
    }
  }
  for (const auto& [edge, count] : edges) ASSERT_EQ(count, 2);
  EXPECT_EQ(static_cast<int64_t>(m->positions.size()) -
                static_cast<int64_t>(edges.size()) +
                static_cast<int64_t>(m->triangles.size()),
            2);
}

}  // namespace
}  // namespace tpr::extract
