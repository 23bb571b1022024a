// The distances the index searches with: non-negative weightings of three
// terms (intent.h),
//
//   d_w(A, B) = w.emd EMD(A, B) + w.spectral S(A, B) + w.heat H(A, B),
//
// EMD the distance of Tam & Lau 2007 (section 6.1, ground distance of Eq.
// 7), S(A, B) = ||E(s_A) - E(s_B)||_2 the spectral term and H(A, B) =
// ||F(s_A) - F(s_B)||_2 the heat-trace term, with s_X the Laplace-Beltrami
// spectrum of X and E, F the fixed embeddings of spectral.h. w = {1, 0, 0}
// is the paper's distance exactly. The index's own distance, which its
// VP-tree splits on, is IndexOptions::build_weights (signature_index.h;
// IntentWeights(Intent::kBalanced) by default).
//
// Why every d_w is a metric (so the VP-tree of section 6.2 stays exact).
//  1. EMD is a pseudometric on signatures: ground_distance.h shows that Eq.
//     7 is a difference norm N(phi(U1) - phi(U2)) of a fixed feature
//     embedding, hence a pseudometric; Rubner et al. [22] prove that the EMD
//     between equal total masses (Prepare normalizes to 1) under such a
//     ground distance satisfies non-negativity, symmetry and the triangle
//     inequality, with EMD(A, A) = 0.
//  2. S and H are pseudometrics: each is the Euclidean distance between the
//     images of one fixed map that depends on nothing but the spectrum and
//     the (index-wide) options. Non-negativity, symmetry, T(A, A) = 0 and
//     T(A, C) <= T(A, B) + T(B, C) are those of the norm.
//  3. A non-negative weighting of pseudometrics is a pseudometric, term by
//     term (intent.h):
//     d_w(A, C) = sum_t w_t T(A, C) <= sum_t w_t [T(A, B) + T(B, C)]
//               = d_w(A, B) + d_w(B, C).
//  Identity of indiscernibles: d_w(A, B) = 0 iff every term with w_t > 0 is
//  0. Distinct signatures at distance 0 are ties, ordered by id like any
//  other tie; the VP-tree needs only symmetry and the triangle inequality.
//
// Lower bounds. With L_t <= T for each term, sum_t w_t L_t <= d_w. The
// index bounds each term separately (vp_tree.h: stored per-term distances
// to the vantage points); EmdLowerBound (emd.h, the centroid bound) is <=
// EMD, and S and H are computed exactly in O(n), so
//   DistanceLowerBound(A, B, w) = w.emd EmdLowerBound(A, B) + w.spectral S
//                                 + w.heat H <= d_w(A, B);
// a search checks this O(bands + n) bound before any EMD.
//
//   GroundDistanceOptions o;                    // Eq. 7 + embeddings
//   PreparedSignature a = *Prepare(x, o), b = *Prepare(y, o);
//   TermWeights w = IntentWeights(Intent::kKind);
//   if (DistanceLowerBound(a, b, w) <= radius) Use(Distance(a, b, w));
#ifndef TPR_INDEXER_LIB_METRIC_H_
#define TPR_INDEXER_LIB_METRIC_H_

#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/intent.h"

namespace tpr::index {

// SpectralDistance returns S(a, b) above. Precondition: a and b prepared
// with the same options (so spectral_size() agree). O(n); thread-safe.
inline double SpectralDistance(const PreparedSignature& a,
                               const PreparedSignature& b) {
  return SpectralDistance(a.spectral(), b.spectral(),
                          static_cast<size_t>(a.spectral_size()));
}

// HeatDistance returns H(a, b) above (0 when the heat-trace term is absent,
// HeatTraceOptions::scales 0). Precondition: a and b prepared with the same
// options. O(m); thread-safe.
inline double HeatDistance(const PreparedSignature& a,
                           const PreparedSignature& b) {
  return SpectralDistance(a.heat(), b.heat(),
                          static_cast<size_t>(a.heat_size()));
}

// Distance returns d_w(a, b), computed with `solver` (one per thread) and
// summed in the order emd, spectral, heat; a term whose factor is 0 is not
// computed (so no EMD when w.emd is 0). Preconditions: w valid
// (ValidateTermWeights), those of EmdSolver::Distance and SpectralDistance.
// Cost: one EMD (when w.emd > 0) plus O(n). Not thread-safe in `solver`.
double Distance(EmdSolver& solver, const PreparedSignature& a,
                const PreparedSignature& b, const TermWeights& w);

// Distance with a thread_local solver (like Emd). Thread-safe.
double Distance(const PreparedSignature& a, const PreparedSignature& b,
                const TermWeights& w);

// DistanceLowerBound returns w.emd EmdLowerBound(a, b) + w.spectral S(a, b)
// + w.heat H(a, b) <= d_w(a, b). Cost O(bands + n), no allocation;
// thread-safe.
double DistanceLowerBound(const PreparedSignature& a,
                          const PreparedSignature& b, const TermWeights& w);

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_METRIC_H_
