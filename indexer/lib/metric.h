// The distance the index searches with (issue 9, item 3): the EMD of Tam &
// Lau 2007 (section 6.1, ground distance of Eq. 7) plus the weighted
// spectral term of spectral.h:
//
//   d(A, B) = EMD(A, B) + S(A, B),   S(A, B) = ||E(s_A) - E(s_B)||_2,
//
// with s_X the Laplace-Beltrami spectrum of X and E the fixed embedding of
// spectral.h (w_s * phi(s) / sqrt(n), phi one per-coordinate map, padded).
// With w_s = 0, S = 0 and d is the paper's distance exactly. The defaults
// (spectral.h: w_s = 1, phi(x) = x / i, the first n = 20 values) were
// chosen by cross-validation over every dev set together (docs/results.md).
//
// Why d is still a metric (so the VP-tree of section 6.2 stays exact).
//  1. EMD is a pseudometric on signatures: ground_distance.h shows that Eq.
//     7 is a difference norm N(phi(U1) - phi(U2)) of a fixed feature
//     embedding, hence a pseudometric; Rubner et al. [22] prove that the EMD
//     between equal total masses (Prepare normalizes to 1) under such a
//     ground distance satisfies non-negativity, symmetry and the triangle
//     inequality, with EMD(A, A) = 0.
//  2. S is a pseudometric: it is the Euclidean distance between the images
//     E(s_A), E(s_B) of one fixed map E that depends on nothing but the
//     spectrum and the (index-wide) options. Non-negativity, symmetry,
//     S(A, A) = 0 and S(A, C) <= S(A, B) + S(B, C) are those of the norm.
//  3. The sum of two pseudometrics is a pseudometric: each of the four
//     properties adds termwise; in particular
//     d(A, C) = EMD(A, C) + S(A, C)
//             <= [EMD(A, B) + EMD(B, C)] + [S(A, B) + S(B, C)]
//             =  d(A, B) + d(B, C).
//  Identity of indiscernibles: d(A, B) = 0 iff EMD(A, B) = 0 AND S(A, B) =
//  0, i.e. the features have the same images and masses (see
//  ground_distance.h) and the first n spectrum values agree (after the
//  Weyl padding of a short spectrum; values past n are not compared). So
//  adding S can only separate signatures the EMD alone confused, never the
//  reverse; d is a true metric on the classes of signatures at distance 0.
//  The VP-tree needs only symmetry and the triangle inequality (its pruning
//  rule |d(q, v) - d(v, x)| <= d(q, x) holds for pseudometrics); distinct
//  signatures at distance 0 are ties, ordered by id like any other tie.
//
// Lower bounds. EmdLowerBound (emd.h, the centroid bound) is <= EMD and S
// is computed exactly in O(n), so
//   S(A, B) <= DistanceLowerBound(A, B) = EmdLowerBound(A, B) + S(A, B)
//          <= d(A, B);
// a search checks this O(bands + n) bound before any EMD.
//
//   GroundDistanceOptions o;                    // Eq. 7 + spectral options
//   PreparedSignature a = *Prepare(x, o), b = *Prepare(y, o);
//   if (DistanceLowerBound(a, b) <= radius) Use(Distance(a, b));
#ifndef TPR_INDEXER_LIB_METRIC_H_
#define TPR_INDEXER_LIB_METRIC_H_

#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"

namespace tpr::index {

// SpectralDistance returns S(a, b) above. Precondition: a and b prepared
// with the same options (so spectral_size() agree). O(n); thread-safe.
inline double SpectralDistance(const PreparedSignature& a,
                               const PreparedSignature& b) {
  return SpectralDistance(a.spectral(), b.spectral(),
                          static_cast<size_t>(a.spectral_size()));
}

// Distance returns d(a, b) = EMD(a, b) + S(a, b), computed with `solver`
// (one per thread). Preconditions: those of EmdSolver::Distance and of
// SpectralDistance. Cost: one EMD plus O(n). Not thread-safe in `solver`.
double Distance(EmdSolver& solver, const PreparedSignature& a,
                const PreparedSignature& b);

// Distance with a thread_local solver (like Emd). Thread-safe.
double Distance(const PreparedSignature& a, const PreparedSignature& b);

// DistanceLowerBound returns EmdLowerBound(a, b) + S(a, b) <= d(a, b).
// Cost O(bands + n), no allocation; thread-safe.
double DistanceLowerBound(const PreparedSignature& a,
                          const PreparedSignature& b);

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_METRIC_H_
