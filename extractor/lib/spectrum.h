// The Laplace-Beltrami spectrum of a triangle mesh ("Shape-DNA", Reuter et
// al. 2006): the first N non-zero eigenvalues of the generalized problem
// L x = lambda M x with the linear-FEM cotangent stiffness L and the
// consistent mass M, scaled by area so that the spectrum is invariant to
// uniform scale. A global, pose-invariant description that complements the
// TPR's local features on similar-skeleton shapes.
//
//   absl::StatusOr<Spectrum> s =
//       LaplaceBeltramiSpectrum(mesh, SpectrumOptions{});
//   // unit sphere: 2, 2, 2, 6, 6, 6, 6, 6, 12, ...
//   if (s.ok()) Store(s->eigenvalues);
#ifndef TPR_EXTRACTOR_LIB_SPECTRUM_H_
#define TPR_EXTRACTOR_LIB_SPECTRUM_H_

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "extractor/lib/decimation.h"  // SimplifyMesh, which it uses
#include "extractor/lib/mesh.h"

namespace tpr::extract {

// SpectrumSolverOptions: how LaplaceBeltramiSpectrum computes, whatever the
// count asked for (the extractor's Options::spectrum; the count is
// Options::spectrum_eigenvalues there, so it has one source).
struct SpectrumSolverOptions {
  // Meshes with more (referenced) vertices than this are first simplified
  // to this many vertices with OpenMesh's quadric decimater
  // (SimplifyMesh, decimation.h). 0 never simplifies. The bound sits well above
  // 10k vertices because below it simplifying costs more than it saves: the
  // decimater's collapses cost more than the eigensolve of the whole mesh
  // (BM_SimplifyMesh against BM_SpectrumFullMesh), and it adds an error of
  // its own (StableUnderSimplification in tests/extractor/spectrum_test.cc
  // states it per eigenvalue, at this bound and at 3000); 16000 also solves
  // registered bodies such as SCAPE's 12,500-vertex meshes whole, so their
  // spectrum is the reference ShapeDNA's (docs/results.md). OpenMesh's
  // faster McDecimaterT is not used: it draws from the global rand(), so
  // the same mesh would not always give the same spectrum. Default 16000.
  int max_vertices = 16000;
  // Shift sigma of the shift-invert Lanczos iteration, in the scaled units
  // of the result (lambda * A / (4 pi)); must be negative so that
  // L - sigma M is positive definite and the zero eigenvalues are found
  // with the others. The eigenvalues nearest sigma converge first. The
  // unit sphere's first non-zero value is 2; elongated shapes go well
  // below 0.1. Default -0.01.
  double shift = -0.01;
  // Relative residual of each Ritz value (Spectra's tol). The eigenvalue
  // error is of the order of the squared residual (1e-12 here), far below
  // the discretization's (percent); on the 10k-vertex biped 1e-6 takes 123
  // Lanczos steps for 50 values against 129 for 1e-8, and
  // UnrestartedAndRestartedLanczosAgree still finds both iterations within
  // 1e-9 of each other. Default 1e-6.
  double tolerance = 1e-6;
  // Vectors the unrestarted Lanczos iteration may hold (V doubles each)
  // before Spectra's implicitly restarted iteration (2 nev + 1 vectors,
  // nev = eigenvalues + components) takes over from scratch; 0 means
  // 3 nev + 20 for nev <= 200 and the restarted iteration alone above (its
  // basis stays at 2 nev + 1 vectors, and each convergence test of the
  // unrestarted one costs O(m^3) in its m vectors). The unrestarted
  // iteration needed about 2.5 nev on the 10k-vertex biped (129 products
  // for nev = 51); a value <= nev goes straight to the restarted one.
  // Default 0.
  int max_lanczos_vectors = 0;
  // Restarts of the implicitly restarted Lanczos iteration (the fallback
  // above) before giving up. Default 1000.
  int max_restarts = 1000;
  // Meshes solved with at most this many vertices use a dense generalized
  // eigensolver (every eigenvalue, exact multiplicities; O(V^3) time and
  // O(V^2) memory, as fast as the iterative solver at 300). In [0, 5000].
  // Default 300.
  int dense_max_vertices = 300;
};

// SpectrumOptions configures LaplaceBeltramiSpectrum: the solver's options
// plus how many eigenvalues to return.
struct SpectrumOptions : SpectrumSolverOptions {
  // Non-zero eigenvalues to return (N). Must be >= 1. Default 50, the
  // extractor's default (Options::spectrum_eigenvalues says why). The cost
  // grows faster than linearly with it (more Lanczos steps, each
  // orthogonalized against more vectors): BM_SpectrumEigenvalues compares
  // 20 with 50, and a whole extraction at 10k vertices stays within 150
  // Dijkstra sweeps with 50 (BM_Extract/10000/1 over BM_Dijkstra/10000,
  // docs/benchmarks.md).
  int eigenvalues = 50;
  // When the mesh solved has too few vertices for `eigenvalues` (V vertices
  // in C components have V - C non-zero eigenvalues; above
  // dense_max_vertices the iterative solver reaches V - C - 1), return that
  // many instead of INVALID_ARGUMENT. Default false.
  bool allow_fewer = false;
};

// Spectrum is the result of LaplaceBeltramiSpectrum.
struct Spectrum {
  // The first N non-zero eigenvalues lambda_i of L x = lambda M x in
  // ascending order, each multiplied by A / (4 pi) (A = the total area of
  // the mesh solved), so a sphere of any radius gives l (l + 1) with
  // multiplicity 2 l + 1: 2, 2, 2, 6 x 5, 12 x 7, ...
  std::vector<double> eigenvalues;
  // Vertices of the mesh that was solved (after simplification).
  int64_t vertices = 0;
  // Connected components (each contributes one zero eigenvalue, skipped).
  int64_t components = 0;
  // Linear solves with the factor of L - sigma M the iteration used.
  int64_t operations = 0;
};

// LaplaceBeltramiSpectrum returns the first options.eigenvalues non-zero
// eigenvalues of the mesh's Laplace-Beltrami operator, scaled as Spectrum
// documents. Discretization: linear finite elements; stiffness
// L_ij = -(cot alpha_ij + cot beta_ij) / 2, mass M_ij = area / 12 per
// incident triangle and M_ii = area / 6 per incident triangle (the
// consistent, not lumped, mass). Boundary edges get the natural (Neumann,
// free) condition. Unreferenced vertices are ignored. Meshes with more than
// options.max_vertices vertices are simplified first (see SimplifyMesh).
// Solver: shift-invert around options.shift with a sparse Cholesky
// (Eigen::SimplicialLDLT, one approximate-minimum-degree ordering per mesh)
// of L - sigma M = L_K D L_K^T, the problem brought to the standard
// symmetric form (D^-1/2 L_K^-1) M (L_K^-T D^-1/2) y = y / (lambda - sigma)
// (Euclidean inner products, cheaper than the generalized mode's M inner
// products; same eigenvalues) for an unrestarted Lanczos iteration with
// full reorthogonalization (spectrum.cc; Spectra's restarted SymEigsSolver
// when it needs more than options.max_lanczos_vectors vectors), checked by
// Sylvester's inertia (further deflated runs find copies of multiple
// eigenvalues a single run missed); meshes of at most
// options.dense_max_vertices vertices are solved densely. One zero eigenvalue
// per connected component is skipped. Preconditions: a mesh that intake
// validated (finite coordinates, indices in range, edge-manifold). Errors:
// INVALID_ARGUMENT for options out of range, a mesh without triangles or with
// zero area, or too few vertices for the requested count unless allow_fewer
// (the message gives the numbers: a mesh of V vertices in C components has V -
// C non-zero eigenvalues); INTERNAL when the factorization or the Lanczos
// iteration fails (non-convergence: the message names the count converged).
// Cost: simplification O(V log V); then, for V' = min(V, max_vertices)
// vertices, one sparse Cholesky (about O(V'^1.5) on a surface mesh) and O(N)
// Lanczos steps of one forward and one backward substitution each; O(N V')
// memory (about 3 N vectors of V' doubles). Thread-safe (pure
// function, no shared state).
absl::StatusOr<Spectrum> LaplaceBeltramiSpectrum(
    const Mesh& mesh, const SpectrumOptions& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_SPECTRUM_H_
