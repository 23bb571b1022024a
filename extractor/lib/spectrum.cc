// Laplace-Beltrami spectrum: linear-FEM matrices assembled here (a dozen
// lines; no Debian library assembles the cotangent/mass pair for our Mesh),
// the eigenproblem solved by Spectra, the simplification by OpenMesh
// (decimation.cc).
#include "extractor/lib/spectrum.h"

#include <Spectra/SymEigsSolver.h>
#include <Spectra/Util/SimpleRandom.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/status_macros.h"
#include "extractor/lib/disjoint_sets.h"
#include "extractor/lib/mesh_clean.h"

namespace tpr::extract {
namespace {

constexpr double kPi = 3.14159265358979323846;

using SparseMatrix = Eigen::SparseMatrix<double>;
// Every factorization works on matrices already permuted by one
// fill-reducing ordering (Permute), so the ordering is computed once per
// mesh instead of once per factorization, and no solve permutes vectors.
using Ldlt = Eigen::SimplicialLDLT<SparseMatrix, Eigen::Lower,
                                   Eigen::NaturalOrdering<int>>;

int64_t CountComponents(const Mesh& mesh) {
  DisjointSets sets(mesh.positions.size());
  for (const auto& t : mesh.triangles) {
    sets.Union(t[0], t[1]);
    sets.Union(t[0], t[2]);
  }
  int64_t components = 0;
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    if (sets.Find(static_cast<int64_t>(v)) == static_cast<int64_t>(v))
      ++components;
  }
  return components;
}

// Assemble builds the cotangent stiffness L and consistent mass M of a
// compact mesh (both full symmetric, on the same pattern: the diagonal and
// the edges of the triangles with non-zero area) and returns its area. Each
// entry sums its contributions in triangle order, as Eigen's setFromTriplets
// would from the triplets (i, j, -w), (j, i, -w), (i, i, w), (j, j, w) per
// corner, but without sorting a dozen triplets per triangle (the triplets
// and their sort were about 10% of the spectrum at 10k vertices, perf).
double Assemble(const Mesh& mesh, SparseMatrix* stiffness, SparseMatrix* mass) {
  const int32_t n = static_cast<int32_t>(mesh.positions.size());
  // Twice the area of each triangle; zero-area triangles contribute nothing
  // to either matrix, not even a pattern entry.
  std::vector<double> twice_areas(mesh.triangles.size());
  std::vector<int32_t> corner_count(n + 1, 0);
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    const Eigen::Vector3d& p0 = mesh.positions[t[0]];
    twice_areas[f] =
        (mesh.positions[t[1]] - p0).cross(mesh.positions[t[2]] - p0).norm();
    if (!(twice_areas[f] > 0.0)) continue;
    for (int k = 0; k < 3; ++k) ++corner_count[t[k] + 1];
  }
  // Triangles around each vertex (compressed rows), then each column's rows:
  // the vertex and its neighbours through those triangles, sorted.
  for (int32_t v = 0; v < n; ++v) corner_count[v + 1] += corner_count[v];
  std::vector<int32_t> corners(corner_count[n]);
  {
    std::vector<int32_t> next(corner_count.begin(), corner_count.end() - 1);
    for (size_t f = 0; f < mesh.triangles.size(); ++f) {
      if (!(twice_areas[f] > 0.0)) continue;
      for (int k = 0; k < 3; ++k)
        corners[next[mesh.triangles[f][k]]++] = static_cast<int32_t>(f);
    }
  }
  std::vector<int> outer(n + 1, 0);
  std::vector<int> inner;
  inner.reserve(static_cast<size_t>(corner_count[n]) * 2 + n);
  std::vector<int32_t> column;
  for (int32_t v = 0; v < n; ++v) {
    column.assign(1, v);
    for (int32_t c = corner_count[v]; c < corner_count[v + 1]; ++c) {
      for (const int32_t u : mesh.triangles[corners[c]]) {
        if (u != v) column.push_back(u);
      }
    }
    std::sort(column.begin(), column.end());
    column.erase(std::unique(column.begin(), column.end()), column.end());
    inner.insert(inner.end(), column.begin(), column.end());
    outer[v + 1] = static_cast<int>(inner.size());
  }
  // The cotangent at corner k of each triangle, opposite edge (k+1, k+2):
  // cot = (u . v) / |u x v| = (u . v) / twice_area.
  std::vector<double> half_cot(3 * mesh.triangles.size(), 0.0);
  double area = 0.0;
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const double twice_area = twice_areas[f];
    if (!(twice_area > 0.0)) continue;
    const auto& t = mesh.triangles[f];
    area += 0.5 * twice_area;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& c = mesh.positions[t[k]];
      half_cot[3 * f + k] = 0.5 *
                            (mesh.positions[t[(k + 1) % 3]] - c)
                                .dot(mesh.positions[t[(k + 2) % 3]] - c) /
                            twice_area;
    }
  }
  // Column by column: its triangles in increasing order, and in each the
  // corners in order, add what the triplets (i, j, -w), (j, i, -w),
  // (i, i, w), (j, j, w) of L and (i, j, a/12), (j, i, a/12),
  // (t_k, t_k, a/6) of M put in this column, so each entry sums the same
  // terms in the same order as setFromTriplets did.
  std::vector<double> l(inner.size(), 0.0), m(inner.size(), 0.0);
  std::vector<int> slot(n, -1);  // row -> entry of the current column
  for (int32_t v = 0; v < n; ++v) {
    for (int e = outer[v]; e < outer[v + 1]; ++e) slot[inner[e]] = e;
    for (int32_t c = corner_count[v]; c < corner_count[v + 1]; ++c) {
      const int32_t f = corners[c];
      const auto& t = mesh.triangles[f];
      const double a = 0.5 * twice_areas[f];
      for (int k = 0; k < 3; ++k) {
        const int32_t i = t[(k + 1) % 3];
        const int32_t j = t[(k + 2) % 3];
        const double w = half_cot[3 * f + k];
        if (j == v) {
          l[slot[i]] += -w;
          m[slot[i]] += a / 12.0;
        }
        if (i == v) {
          l[slot[j]] += -w;
          m[slot[j]] += a / 12.0;
        }
        if (i == v) l[slot[i]] += w;
        if (j == v) l[slot[j]] += w;
        if (t[k] == v) m[slot[v]] += a / 6.0;
      }
    }
  }
  for (auto [matrix, values] : {std::pair{stiffness, &l}, {mass, &m}}) {
    matrix->resize(n, n);
    matrix->resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
    std::copy(outer.begin(), outer.end(), matrix->outerIndexPtr());
    std::copy(inner.begin(), inner.end(), matrix->innerIndexPtr());
    std::copy(values->begin(), values->end(), matrix->valuePtr());
  }
  return area;
}

// Permute reorders the rows and columns of the symmetric L and M alike by
// the approximate minimum degree ordering of their common pattern (Eigen's
// AMDOrdering, the one SimplicialLDLT would compute on every call). The
// generalized eigenvalues do not change (P L P^T x = lambda P M P^T x with
// x = P y); the eigenvectors are only used, in the same ordering, for
// deflation.
void Permute(SparseMatrix* stiffness, SparseMatrix* mass) {
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> inverse;
  Eigen::AMDOrdering<int> amd;
  amd(stiffness->selfadjointView<Eigen::Lower>(), inverse);
  const Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> p =
      inverse.inverse();
  SparseMatrix l, m;
  l = stiffness->twistedBy(p);
  m = mass->twistedBy(p);
  *stiffness = std::move(l);
  *mass = std::move(m);
}

// SolveByColumns overwrites x with T^-1 x for the unit triangular T whose
// strictly triangular part `columns` holds by compressed columns, when T^T
// is lower triangular (forward = false: T = L^T, solved from the last
// unknown up) or upper triangular (forward = true: T = L, `columns` = the
// strictly lower part of L transposed, solved from the first unknown down).
// Each unknown is its right-hand side minus the dot product of one stored
// column with the unknowns already solved. Written by hand because Eigen's
// sparse triangular solves either scatter column updates into x (the
// forward solve) or sum each dot product in one accumulator after walking
// past the entries on the wrong side of the diagonal (the transposed
// solve): a chain of dependent additions that perf showed as 40% of the
// operator's time at 10k vertices. Four partial sums break the chain; the
// result differs from Eigen's only by the rounding of the reassociated sums.
void SolveByColumns(const SparseMatrix& columns, bool forward, double* x) {
  const int* outer = columns.outerIndexPtr();
  const int* row = columns.innerIndexPtr();
  const double* value = columns.valuePtr();
  const int n = static_cast<int>(columns.cols());
  for (int step = 0; step < n; ++step) {
    const int j = forward ? step : n - 1 - step;
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    int k = outer[j];
    const int end = outer[j + 1];
    for (; k + 4 <= end; k += 4) {
      s0 += value[k] * x[row[k]];
      s1 += value[k + 1] * x[row[k + 1]];
      s2 += value[k + 2] * x[row[k + 2]];
      s3 += value[k + 3] * x[row[k + 3]];
    }
    for (; k < end; ++k) s0 += value[k] * x[row[k]];
    x[j] -= (s0 + s1) + (s2 + s3);
  }
}

// ShiftInvertOp is the generalized problem L x = lambda M x, shifted and
// inverted, brought to standard symmetric form for Spectra's SymEigsSolver:
// with K = L - sigma M = L_K D L_K^T (sparse LDL^T; K is symmetric positive
// definite for sigma < 0, so D > 0) and R = D^(1/2) L_K^T,
//
//   A = R^-T M R^-1,   A y = mu y  <=>  L x = lambda M x,
//   mu = 1 / (lambda - sigma),  y = R x.
//
// One product costs what Spectra's generalized shift-invert mode
// (SymGEigsShiftSolver) pays per step for its operator (K^-1 M x: one
// product with M, one forward and one backward substitution), but the
// Lanczos basis is then orthogonal in the plain Euclidean inner product:
// the generalized mode takes every inner product, norm and
// re-orthogonalization in the M inner product, three to five more products
// with M per step, which were about 40% of the whole solve at 10k vertices
// (perf, docs/benchmarks.md). The eigenvalues are the same in exact
// arithmetic; the convergence test (relative to mu) is Spectra's in either
// mode. With deflation vectors Y (orthonormal eigenvectors of A already
// found) it returns P A x, P = I - Y Y^T: still symmetric, maps Y to 0 and
// keeps the other eigenpairs, so a further run finds what the first missed.
class ShiftInvertOp {
 public:
  using Scalar = double;
  ShiftInvertOp(const SparseMatrix& l, const SparseMatrix& m, double sigma)
      : m_(m), work_(l.rows()) {
    solver_.compute(SparseMatrix(l - sigma * m));
    ok_ = solver_.info() == Eigen::Success;
    if (ok_) {
      const Eigen::VectorXd d = solver_.vectorD();
      ok_ = (d.array() > 0.0).all();
      inverse_sqrt_d_ = d.array().max(1e-300).rsqrt();
      // SimplicialLDLT keeps L_K's unit diagonal implicit: its matrix holds
      // the strictly lower part by columns, and its transpose the same by
      // rows.
      lower_ = &solver_.matrixL().nestedExpression();
      ok_ = lower_->isCompressed();
      lower_by_rows_ = lower_->transpose();
    }
  }
  Eigen::Index rows() const { return m_.rows(); }
  Eigen::Index cols() const { return m_.cols(); }
  void perform_op(const double* x_in, double* y_out) const {
    Eigen::Map<const Eigen::VectorXd> x(x_in, rows());
    Eigen::Map<Eigen::VectorXd> y(y_out, rows());
    work_ = inverse_sqrt_d_.cwiseProduct(x);
    SolveByColumns(*lower_, /*forward=*/false, work_.data());  // L_K^-T
    // M is symmetric: its columns are its rows, and the transposed product
    // sums each row's dot product instead of scattering column updates.
    y.noalias() = m_.transpose() * work_;
    SolveByColumns(lower_by_rows_, /*forward=*/true, y.data());  // L_K^-1
    y.array() *= inverse_sqrt_d_.array();
    if (deflation_.cols() > 0) {
      const Eigen::VectorXd coefficients = deflation_.transpose() * y;
      y.noalias() -= deflation_ * coefficients;
    }
  }
  // ok is false when K was not factored as positive definite.
  bool ok() const { return ok_; }
  // Deflate replaces the deflation vectors (orthonormal columns).
  void Deflate(Eigen::MatrixXd vectors) { deflation_ = std::move(vectors); }

 private:
  const SparseMatrix& m_;
  Ldlt solver_;
  // The strictly lower part of L_K by columns and by rows, for
  // SolveByColumns.
  const SparseMatrix* lower_ = nullptr;
  SparseMatrix lower_by_rows_;
  bool ok_ = false;
  Eigen::VectorXd inverse_sqrt_d_;
  Eigen::MatrixXd deflation_;
  mutable Eigen::VectorXd work_;
};

// EigenvaluesBelow returns how many eigenvalues of L x = lambda M x are
// below tau (Sylvester's law of inertia: the negative pivots of an LDL^T
// of L - tau M), or -1 when the factorization fails (tau on an eigenvalue).
int64_t EigenvaluesBelow(const SparseMatrix& l, const SparseMatrix& m,
                         double tau) {
  Ldlt ldlt(SparseMatrix(l - tau * m));
  if (ldlt.info() != Eigen::Success) return -1;
  const Eigen::VectorXd d = ldlt.vectorD();
  return static_cast<int64_t>((d.array() < 0.0).count());
}

// Eigenpairs are the converged pairs of one Lanczos run: the eigenvalues
// lambda ascending, and the matching eigenvectors of ShiftInvertOp's A
// (orthonormal columns), held as basis * coefficients and formed only when
// a deflated run needs them (a product of V x m and m x nev).
struct Eigenpairs {
  Eigen::VectorXd values;
  Eigen::MatrixXd basis;
  Eigen::MatrixXd coefficients;
  int64_t operations = 0;
};

// SubtractBasis sets w -= basis.leftCols(k) * c, eight columns at a time.
// Eigen's product with a k-column block (k < 128) walks the rows once and
// reads all k columns at each row, k streams a page apart that the
// hardware prefetcher does not follow; on the 10k-vertex biped that
// product took 24% of a 50-eigenvalue spectrum inside Spectra, against 14%
// for the transposed product that reads the same columns one after another
// (perf, docs/benchmarks.md). Eight columns at a time cost one more pass
// over w (in cache) per block.
void SubtractBasis(const Eigen::MatrixXd& basis, int64_t k,
                   const Eigen::VectorXd& c, Eigen::VectorXd* w) {
  constexpr int64_t kBlock = 8;
  for (int64_t j = 0; j < k; j += kBlock) {
    const int64_t b = std::min(kBlock, k - j);
    w->noalias() -= basis.middleCols(j, b) * c.segment(j, b);
  }
}

// RunPlainLanczos is the symmetric Lanczos iteration on op without
// restarts, with partial reorthogonalization: a new vector is orthogonalized
// against the whole basis (classical Gram-Schmidt with the DGKS criterion, a
// second pass only when the first removed more than 1 - 1/sqrt(2) of the
// vector's norm) only when its estimated loss of orthogonality asks for it
// (see the loop), until
// the nev largest Ritz values mu of the tridiagonal T pass Spectra's test
// (residual |beta_m s_mi| < tol max(eps^(2/3), |mu_i|)) or the basis
// reaches max_basis vectors; *converged says which. Written by hand, beside
// Spectra (kept for the restarted fallback), because at 50 eigenvalues
// Spectra's implicitly restarted Lanczos spent as much time in its dense
// bookkeeping as in the operator: it orthogonalizes with one product of
// each kind and a third to check (three passes over the basis per step)
// through the slow Eigen product SubtractBasis avoids, and each restart
// applies the implicit QR shifts to the whole basis. Here a step costs no
// pass over the basis unless the orthogonality estimate asks for two (DGKS
// rarely asks for the second after the three-term recurrence); the memory
// is the basis, max_basis x V doubles. The start
// vector is Spectra's (its SimpleRandom with seed 0), so runs are
// reproducible.
absl::StatusOr<Eigenpairs> RunPlainLanczos(const ShiftInvertOp& op, int64_t nev,
                                           double sigma, int64_t max_basis,
                                           const SpectrumOptions& options,
                                           bool* converged) {
  *converged = false;
  const int64_t n = op.rows();
  max_basis = std::min(max_basis, n);
  Eigenpairs out;
  Eigen::MatrixXd basis(n, max_basis);
  Eigen::VectorXd alpha(max_basis), beta(max_basis);
  Eigen::VectorXd w(n), c(max_basis);
  {
    Spectra::SimpleRandom<double> rng(0);
    basis.col(0) = rng.random_vec(n);
    basis.col(0).normalize();
  }
  const double eps23 =
      std::pow(std::numeric_limits<double>::epsilon(), 2.0 / 3.0);
  // Each convergence test costs an m x m tridiagonal eigendecomposition,
  // O(m^3) (about 1.5 ms at m = 125), each product beyond convergence
  // about 0.5 ms at 10k vertices. On the 10k biped all nev pairs pass at
  // m = 2.6 nev (nev = 21) and 2.45 nev (nev = 51); so the first test is at
  // 2.3 nev + 1 vectors, the next ones every twentieth of the basis.
  int64_t next_test = std::min<int64_t>(max_basis, 23 * nev / 10 + 1);
  // omega_*[k] estimate q_k . q_{j-1}, q_j and q_{j+1} (Simon's
  // recurrence, below).
  const double eps = std::numeric_limits<double>::epsilon();
  const double semi = std::sqrt(eps);
  Eigen::VectorXd omega_prev = Eigen::VectorXd::Zero(max_basis + 1);
  Eigen::VectorXd omega_cur = Eigen::VectorXd::Zero(max_basis + 1);
  Eigen::VectorXd omega_new = Eigen::VectorXd::Zero(max_basis + 1);
  omega_cur[0] = 1.0;
  double op_norm = 0.0;
  bool reorthogonalize_next = false;
  for (int64_t j = 0; j < max_basis; ++j) {
    op.perform_op(basis.col(j).data(), w.data());
    ++out.operations;
    double a = basis.col(j).dot(w);
    w.noalias() -= a * basis.col(j);
    if (j > 0) w.noalias() -= beta[j - 1] * basis.col(j - 1);
    {
      // The local second pass against q_j alone (one vector, in cache).
      const double again = basis.col(j).dot(w);
      w.noalias() -= again * basis.col(j);
      a += again;
    }
    double norm = w.norm();
    op_norm = std::max(op_norm, std::abs(a) + norm + (j > 0 ? beta[j - 1] : 0));
    // Partial reorthogonalization (Simon 1984): the recurrence
    //   beta_j w_{j+1,k} = beta_k w_{j,k+1} + (alpha_k - alpha_j) w_{j,k}
    //                      + beta_{k-1} w_{j,k-1} - beta_{j-1} w_{j-1,k}
    // plus a rounding term estimates each q_{j+1} . q_k without touching
    // the basis; only when one exceeds sqrt(eps) is the new vector (and the
    // next, Grcar's rule) orthogonalized against the whole basis. The
    // basis then stays semi-orthogonal, which keeps the Ritz values of T
    // accurate to rounding (no spurious copies), at a fraction of the
    // passes over the basis that full reorthogonalization makes.
    double largest = 0.0;
    if (norm > 0.0) {
      for (int64_t k = 0; k < j; ++k) {
        double v = beta[k] * omega_cur[k + 1] + (alpha[k] - a) * omega_cur[k] -
                   (j > 0 ? beta[j - 1] * omega_prev[k] : 0.0);
        if (k > 0) v += beta[k - 1] * omega_cur[k - 1];
        v = (v + std::copysign(eps * op_norm, v)) / norm;
        omega_new[k] = v;
        largest = std::max(largest, std::abs(v));
      }
      omega_new[j] = eps * op_norm / norm;
    }
    if (reorthogonalize_next || largest > semi || !(norm > 0.0)) {
      for (int pass = 0; pass < 2; ++pass) {
        c.head(j + 1).noalias() = basis.leftCols(j + 1).transpose() * w;
        SubtractBasis(basis, j + 1, c, &w);
        a += c[j];
        const double before = norm;
        norm = w.norm();
        if (norm > before * 0.7071) break;
      }
      omega_new.head(j + 1).setConstant(eps);
      reorthogonalize_next = !reorthogonalize_next;
    }
    omega_new[j + 1] = 1.0;
    std::swap(omega_prev, omega_cur);
    std::swap(omega_cur, omega_new);
    alpha[j] = a;
    beta[j] = norm;
    const int64_t m = j + 1;
    const bool breakdown =
        !(norm > std::numeric_limits<double>::epsilon() * std::abs(a));
    if (m >= nev && (m == next_test || m == max_basis || breakdown)) {
      next_test = m + std::max<int64_t>(4, m / 20);
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> tri;
      tri.computeFromTridiagonal(alpha.head(m), beta.head(m - 1),
                                 Eigen::ComputeEigenvectors);
      if (tri.info() != Eigen::Success) {
        return absl::InternalError("spectrum: tridiagonal eigensolver failed");
      }
      // Eigen sorts ascending: the nev largest mu are the last columns.
      bool all = true;
      for (int64_t i = 0; i < nev && all; ++i) {
        const int64_t col = m - 1 - i;
        const double mu = tri.eigenvalues()[col];
        const double residual =
            std::abs(tri.eigenvectors()(m - 1, col)) * (breakdown ? 0.0 : norm);
        all = residual < options.tolerance * std::max(eps23, std::abs(mu));
      }
      if (all) {
        *converged = true;
        out.values.resize(nev);
        out.coefficients.resize(m, nev);
        for (int64_t i = 0; i < nev; ++i) {
          const int64_t col = m - 1 - i;
          out.values[i] = sigma + 1.0 / tri.eigenvalues()[col];  // ascending
          out.coefficients.col(i) = tri.eigenvectors().col(col);
        }
        out.basis = basis.leftCols(m);
        return out;
      }
    }
    if (breakdown || m == max_basis) break;
    basis.col(j + 1) = w / norm;
  }
  return out;
}

// RunRestartedLanczos is Spectra's implicitly restarted Lanczos
// (SymEigsSolver) for the nev largest mu of op.
absl::StatusOr<Eigenpairs> RunRestartedLanczos(ShiftInvertOp& op, int64_t nev,
                                               double sigma,
                                               const SpectrumOptions& options) {
  // Spectra requires nev < ncv <= n and advises ncv >= 2 nev. Between
  // nev + 10 and 2 nev + 1, ncv changed neither the number of solves
  // (about 130 for 51 values) nor the time much; for 21 values on a
  // 9.5k-vertex mesh, ncv 35, 43 (2 nev + 1), 55 and 70 took 71, 66, 73
  // and 71 solves and 2 nev + 1 was the fastest.
  const int64_t ncv = std::min<int64_t>(op.rows(), 2 * nev + 1);
  Eigenpairs out;
  try {
    Spectra::SymEigsSolver<ShiftInvertOp> solver(op, nev, ncv);
    solver.init();
    // The largest mu = 1 / (lambda - sigma) are the smallest lambda.
    const Eigen::Index converged =
        solver.compute(Spectra::SortRule::LargestAlge, options.max_restarts,
                       options.tolerance, Spectra::SortRule::LargestAlge);
    out.operations = solver.num_operations();
    if (solver.info() != Spectra::CompInfo::Successful || converged < nev) {
      return absl::InternalError(absl::StrCat(
          "spectrum: Lanczos iteration did not converge (", converged, " of ",
          nev, " eigenvalues after ", solver.num_iterations(), " restarts)"));
    }
    const Eigen::VectorXd mu = solver.eigenvalues();  // descending
    out.values = sigma + mu.array().inverse();        // ascending
    out.basis = solver.eigenvectors();
    out.coefficients = Eigen::MatrixXd::Identity(nev, nev);
  } catch (const std::exception& e) {
    return absl::InternalError(
        absl::StrCat("spectrum: eigensolver failed: ", e.what()));
  }
  return out;
}

absl::StatusOr<Eigenpairs> RunLanczos(ShiftInvertOp& op, int64_t nev,
                                      double sigma,
                                      const SpectrumOptions& options) {
  // The plain iteration first, with room for three times the wanted
  // pairs; if that is not enough (clustered spectra), Spectra's restarted
  // iteration, whose memory stays at 2 nev + 1 vectors.
  constexpr int64_t kMaxUnrestartedPairs = 200;
  const int64_t max_basis = options.max_lanczos_vectors > 0
                                ? options.max_lanczos_vectors
                            : nev <= kMaxUnrestartedPairs ? 3 * nev + 20
                                                          : 0;
  Eigenpairs plain;
  if (max_basis > nev) {
    bool converged = false;
    TPR_ASSIGN_OR_RETURN(
        plain, RunPlainLanczos(op, nev, sigma, max_basis, options, &converged));
    if (converged) return plain;
  }
  TPR_ASSIGN_OR_RETURN(Eigenpairs out,
                       RunRestartedLanczos(op, nev, sigma, options));
  out.operations += plain.operations;
  return out;
}

absl::Status ValidateOptions(const SpectrumOptions& o) {
  if (o.eigenvalues < 1 || o.eigenvalues > 10000) {
    return absl::InvalidArgumentError(absl::StrCat(
        "spectrum options: eigenvalues ", o.eigenvalues, " not in [1, 10000]"));
  }
  if (o.max_vertices != 0 && o.max_vertices < 4) {
    return absl::InvalidArgumentError(
        "spectrum options: max_vertices must be 0 or >= 4");
  }
  if (!(o.shift < 0.0) || !std::isfinite(o.shift)) {
    return absl::InvalidArgumentError(
        "spectrum options: shift must be negative and finite");
  }
  if (!(o.tolerance > 0.0 && o.tolerance < 1.0)) {
    return absl::InvalidArgumentError(
        "spectrum options: tolerance not in (0, 1)");
  }
  if (o.dense_max_vertices < 0 || o.dense_max_vertices > 5000) {
    return absl::InvalidArgumentError(
        "spectrum options: dense_max_vertices not in [0, 5000]");
  }
  if (o.max_lanczos_vectors < 0) {
    return absl::InvalidArgumentError(
        "spectrum options: max_lanczos_vectors must be >= 0");
  }
  if (o.max_restarts < 1) {
    return absl::InvalidArgumentError(
        "spectrum options: max_restarts must be >= 1");
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<Spectrum> LaplaceBeltramiSpectrum(
    const Mesh& mesh, const SpectrumOptions& options) {
  TPR_RETURN_IF_ERROR(ValidateOptions(options));
  if (mesh.triangles.empty()) {
    return absl::InvalidArgumentError("spectrum: mesh has no triangle");
  }
  Mesh work;
  if (options.max_vertices > 0 &&
      static_cast<int64_t>(mesh.positions.size()) > options.max_vertices) {
    TPR_ASSIGN_OR_RETURN(work, SimplifyMesh(mesh, options.max_vertices));
  } else {
    // Unreferenced vertices would make a zero row of M.
    work = mesh;
    CompactVertices(&work.positions, &work.triangles,
                    VertexOrder::kFirstReference);
  }
  Spectrum result;
  result.vertices = static_cast<int64_t>(work.positions.size());
  result.components = CountComponents(work);
  // Small meshes are solved densely (every eigenvalue, exact multiplicity);
  // the shift-invert Lanczos needs nev = wanted + C < V.
  const bool dense = result.vertices <= options.dense_max_vertices;
  const int64_t reachable =
      result.vertices - result.components - (dense ? 0 : 1);
  int64_t wanted = options.eigenvalues;
  if (wanted > reachable) {
    if (!options.allow_fewer || reachable < 1) {
      return absl::InvalidArgumentError(absl::StrCat(
          "spectrum: ", wanted,
          " non-zero eigenvalues requested but the mesh solved has ",
          result.vertices, " vertices in ", result.components,
          " components, so at most ", std::max<int64_t>(0, reachable)));
    }
    wanted = reachable;
  }
  SparseMatrix stiffness, mass;
  const double area = Assemble(work, &stiffness, &mass);
  if (!(area > 0.0) || !std::isfinite(area)) {
    return absl::InvalidArgumentError("spectrum: mesh has zero surface area");
  }
  const double scale =
      area / (4.0 * kPi);  // lambda * scale is the stored value
  const double sigma = options.shift / scale;

  // One Lanczos run finds, in exact arithmetic, one vector per eigenspace
  // (a single-vector Krylov space), so the copies of an exactly multiple
  // eigenvalue (symmetric meshes: the icosphere's 2 l + 1) can be missed
  // while the run still reports convergence. Sylvester's inertia counts the
  // eigenvalues below the largest one found; while some are missing,
  // another run on the operator deflated by everything found so far picks
  // them up.
  const int64_t nev = wanted + result.components;
  if (dense) {
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> solver(
        Eigen::MatrixXd(stiffness), Eigen::MatrixXd(mass),
        Eigen::EigenvaluesOnly);
    if (solver.info() != Eigen::Success) {
      return absl::InternalError("spectrum: dense eigensolver failed");
    }
    for (int64_t i = result.components; i < nev; ++i) {
      result.eigenvalues.push_back(std::max(0.0, solver.eigenvalues()[i]) *
                                   scale);
    }
    return result;
  }
  Permute(&stiffness, &mass);
  ShiftInvertOp op(stiffness, mass, sigma);
  if (!op.ok()) {
    return absl::InternalError(
        "spectrum: sparse Cholesky of L - sigma M failed");
  }
  std::vector<double> found;
  Eigen::MatrixXd vectors(result.vertices, 0);  // deflation, when needed
  std::vector<Eigenpairs> pending;              // runs not yet in vectors
  constexpr int kMaxRuns = 8;
  int64_t missing = 0;
  for (int run = 0;; ++run) {
    const int64_t request = std::min<int64_t>(
        run == 0 ? nev : std::max<int64_t>(8, missing + 4),
        result.vertices - static_cast<int64_t>(found.size()) - 1);
    if (request < 1) {
      return absl::InternalError(
          "spectrum: no room left for a deflated Lanczos run");
    }
    TPR_ASSIGN_OR_RETURN(Eigenpairs pairs,
                         RunLanczos(op, request, sigma, options));
    result.operations += pairs.operations;
    found.insert(found.end(), pairs.values.data(),
                 pairs.values.data() + pairs.values.size());
    std::sort(found.begin(), found.end());
    if (static_cast<int64_t>(found.size()) > nev) found.resize(nev);
    pending.push_back(std::move(pairs));
    // Every eigenvalue below just under the nev-th found must be among the
    // found (copies equal to the nev-th itself may lie beyond index nev).
    // A tau on an eigenvalue fails the factorization; nudge it.
    int64_t below = -1;
    double tau = 0.0;
    for (double nudge = 1e-6; below < 0 && nudge < 1e-2; nudge *= 10.0) {
      tau = found.back() * (1.0 - nudge);
      below = EigenvaluesBelow(stiffness, mass, tau);
    }
    if (below < 0) {
      return absl::InternalError(
          "spectrum: inertia check factorization failed");
    }
    const int64_t found_below =
        std::lower_bound(found.begin(), found.end(), tau) - found.begin();
    missing = below - found_below;
    if (missing <= 0) break;
    if (run + 1 == kMaxRuns) {
      return absl::InternalError(absl::StrCat(
          "spectrum: ", missing, " eigenvalues still missing after ", kMaxRuns,
          " deflated Lanczos runs"));
    }
    for (const Eigenpairs& p : pending) {
      Eigen::MatrixXd all(result.vertices, vectors.cols() + p.values.size());
      all << vectors, p.basis * p.coefficients;
      vectors = std::move(all);
    }
    pending.clear();
    op.Deflate(vectors);
  }
  // Ascending; the first `components` are the zero eigenvalues.
  result.eigenvalues.reserve(wanted);
  for (int64_t i = result.components; i < nev; ++i) {
    result.eigenvalues.push_back(std::max(0.0, found[i]) * scale);
  }
  return result;
}

}  // namespace tpr::extract
