// Earth Mover's Distance between two prepared signatures (Tam & Lau 2007,
// section 6.1; Rubner et al. [22]), exact, plus its centroid lower bound.
//
//   EmdSolver solver;                                   // one per thread
//   double d = solver.Distance(p, q);                   // exact EMD
//   if (EmdLowerBound(p, q) > radius) Skip();           // O(bands) filter
//
// Both signatures carry total mass 1 (Prepare normalizes), so the EMD is the
// minimum over transport plans f >= 0 with row sums w_p and column sums w_q
// of sum_ij f_ij Dist(p_i, q_j), with Dist the ground distance of Eq. 7.
// Under equal masses and a metric ground distance the EMD is a metric [22]
// (see ground_distance.h for the pseudometric fine print).
#ifndef TPR_INDEXER_LIB_EMD_H_
#define TPR_INDEXER_LIB_EMD_H_

#include <cstdint>
#include <vector>

#include "indexer/lib/ground_distance.h"

namespace tpr::index {

// EmdStats: work done by the last EmdSolver::Distance call.
struct EmdStats {
  // Simplex pivots, degenerate ones included.
  int64_t pivots = 0;
  // Pivots that moved no mass (degenerate).
  int64_t degenerate_pivots = 0;
};

// EmdSolver computes exact EMDs with a network simplex specialized for small
// dense transportation problems, reusing its buffers: after the first call
// at a given size, Distance allocates nothing. Not thread-safe: use one
// solver per thread (Emd() below does that for you).
class EmdSolver {
 public:
  EmdSolver();
  ~EmdSolver();
  EmdSolver(const EmdSolver&) = delete;
  EmdSolver& operator=(const EmdSolver&) = delete;
  EmdSolver(EmdSolver&&) noexcept;
  EmdSolver& operator=(EmdSolver&&) noexcept;

  // Distance returns the exact EMD between `a` and `b` (>= 0; 0 when they
  // are identical). Preconditions (asserted in debug builds): both come
  // from Prepare with the same options, so 1 <= size() <= kMaxFeatures.
  // Cost: the n x m ground-distance matrix plus about 1.5 (n + m) simplex
  // pivots in practice, each O(cycle + moved subtree), one vectorized
  // O(n m) pricing pass every 3 to 5 pivots (BM_Emd beside LEMON's
  // network simplex, BM_EmdLemon; figures in docs/benchmarks.md).
  double Distance(const PreparedSignature& a, const PreparedSignature& b);

  // RelaxedBound returns the relaxed transport bound RelaxedTransportBound
  // (below) of the pair and keeps its ground-distance matrix, so that a
  // following Distance(a, b) of the same pair (same serial()s, no other
  // call in between) does not compute it again. Same preconditions as
  // Distance. Cost: the n x m matrix plus O(n m); no allocation after
  // warm-up.
  double RelaxedBound(const PreparedSignature& a, const PreparedSignature& b);

  // Stats returns the work done by the last Distance call.
  const EmdStats& Stats() const;

  // LastFlow returns the optimal plan of the last Distance call as
  // (i, j, mass) triples with mass > 0, for tests and explanations.
  struct FlowEntry {
    int i;
    int j;
    double mass;
  };
  std::vector<FlowEntry> LastFlow() const;

 private:
  struct Impl;
  Impl* impl_;
};

// Emd returns EmdSolver::Distance(a, b) using a thread_local solver.
// Same preconditions and cost; thread-safe.
double Emd(const PreparedSignature& a, const PreparedSignature& b);

// EmdLowerBound returns N(Centroid(a) - Centroid(b)) <= Emd(a, b), the
// centroid bound of Rubner et al. [22], where N is the norm of which the
// ground distance is the difference norm (see ground_distance.h). Both
// centroids are computed on the fly (a search computes the query's once
// and reads its items' from a CentroidTable instead).
// Cost O((a.size() + b.size()) x bands), no allocation; thread-safe.
double EmdLowerBound(const PreparedSignature& a, const PreparedSignature& b);

// Centroid returns sum_i weight(i) phi32(U_i) of `p`, computed in double
// from coords() in the order EmdLowerBound uses (so CentroidBound on two
// Centroid results equals EmdLowerBound bit for bit): p.rows() values in
// row order [g, K x bands, A x bands, H x bands]. Cost O(size x bands);
// thread-safe.
std::vector<double> Centroid(const PreparedSignature& p);

// RelaxedTransportBound returns the relaxed transport bound of Kusner et
// al. (2015, "From word embeddings to document distances", RWMD):
//   max( sum_i w_i min_j Dist(a_i, b_j), sum_j w'_j min_i Dist(a_i, b_j) )
// which is <= Emd(a, b) (proof in emd.cc) and, unlike the centroid bound,
// sees how the features pair up, so it is much tighter between signatures
// of different shapes. Uses the thread_local solver of Emd(), so a
// following Emd(a, b) on the same thread reuses the ground-distance matrix.
// Cost: the n x m ground-distance matrix (about a quarter of an EMD at
// n = m = 30) plus O(n m); thread-safe.
double RelaxedTransportBound(const PreparedSignature& a,
                             const PreparedSignature& b);

// CentroidBound returns N(ca - cb) for raw centroids laid out as Centroid
// returns them ([g, K x ba, A x ba, H x ba] and the same for b with bb
// bands; missing bands count as zero): EmdLowerBound for callers that keep
// centroids apart from their signatures. O(bands), no allocation;
// thread-safe.
double CentroidBound(const double* ca, int ba, const double* cb, int bb);

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_EMD_H_
