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

#include <cmath>
#include <cstddef>
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

  // ConstrainedBound returns ConstrainedTransportBound (below) of the pair
  // and keeps its ground-distance matrix as RelaxedBound does. Same
  // preconditions. Cost: the n x m matrix plus O(n m) (O(n m^2) at worst,
  // when no feature's nearest partner can take its mass); no allocation
  // after warm-up.
  double ConstrainedBound(const PreparedSignature& a,
                          const PreparedSignature& b);

  // ConstrainedBound32 returns ConstrainedTransportBound32 (below) of the
  // pair. It keeps no double matrix: a following Distance(a, b) computes
  // its own (the float32 path), unless the float32 kernel is unavailable
  // and this fell back to ConstrainedBound. Same preconditions. Cost: the
  // float32 n x m matrix plus O(n m); no allocation after warm-up.
  double ConstrainedBound32(const PreparedSignature& a,
                            const PreparedSignature& b);

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
  // Checks the preconditions (debug builds), then loads the pair's masses
  // and, unless it holds it already, its ground-distance matrix.
  Impl& LoadPair(const PreparedSignature& a, const PreparedSignature& b);
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

// EmdLowerBound with a's centroid given (Centroid(a), a_bands bands), as a
// search that computed its query's once calls it: equals EmdLowerBound(a,
// b) bit for bit. Cost O(b.size() x bands), no allocation; thread-safe.
double EmdLowerBound(const double* a_centroid, int a_bands,
                     const PreparedSignature& b);

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

// ConstrainedTransportBound returns the relaxed transport bound with
// capacities (Atasu and Mittelholzer 2019, "ICT"): each feature of a ships
// its mass w_i to b's features cheapest first, but at most w'_j to feature
// j (the column sums are dropped, the capacities f_ij <= w'_j they imply
// are kept), and the same from b's side; the maximum of the two costs.
// RelaxedTransportBound <= it <= Emd(a, b) (proof in emd.cc); the two
// are equal where every feature's nearest partner can take all its mass,
// and it is tighter where masses differ (a feature split in two, a large
// feature against small ones). This is the bound a search checks before
// the EMD (signature_index.h). Uses the thread_local solver of Emd(), so a
// following Emd(a, b) on the same thread reuses the ground-distance
// matrix. Cost: that of RelaxedTransportBound plus a few O(m) scans per
// feature whose nearest partner is too small; thread-safe.
double ConstrainedTransportBound(const PreparedSignature& a,
                                 const PreparedSignature& b);

// ConstrainedTransportBound32 returns ConstrainedTransportBound computed on
// a float32 ground-distance matrix (internal::GroundDistanceMatrix32 in
// internal/ground_distance_kernels.h: 16 AVX-512F or 8 AVX2 lanes, the
// same values, no widening) and divided by 1 + theta, theta =
// internal::Float32MatrixError(bands) (about 2e-6 at 20 bands), the
// rounding margin that keeps it a lower bound (proof in emd.cc):
//   (1 - 2 theta) ConstrainedTransportBound <= it
//                                           <= ConstrainedTransportBound
//                                           <= Emd(a, b).
// A search's level-2 bound: most items it bounds never reach the EMD,
// which then computes its own double matrix. Where the float32 kernel is
// unavailable (the scalar kernel level, or band counts that differ) it is
// ConstrainedTransportBound itself. Uses the thread_local solver of Emd().
// Cost: about half the arithmetic of the double matrix plus O(n m);
// thread-safe.
double ConstrainedTransportBound32(const PreparedSignature& a,
                                   const PreparedSignature& b);

// PrefetchSignature asks the CPU to start loading p's stored values (its
// one heap block: masses, spectral embedding, coordinates) into cache,
// without waiting: a search calls it for the item it will likely bound
// next (QuerySpec::prefetch), so that the misses of a signature not in
// cache overlap the current item's work instead of stalling the ground
// distance matrix. No effect on any result. Cost: one prefetch
// instruction per 64 bytes (about 54 at 14 features, 20 bands); none on
// compilers without __builtin_prefetch. Thread-safe.
void PrefetchSignature(const PreparedSignature& p);

// PrefetchSignatureEarly is the search's policy for PrefetchSignature on
// an item still at level 0 of the cascade (only its centroid row is
// certain to be read): true while at least half of the items bounded at
// level 1 so far went on to level 2 (and before any was bounded), given
// the counts of level-1 and level-2 bounds computed so far. An item that
// fails level 1 never reads its signature, and a prefetch of 3.5 KB that
// is not read costs memory bandwidth and the miss queue. O(1).
inline bool PrefetchSignatureEarly(int64_t level1_bounds,
                                   int64_t level2_bounds) {
  return 2 * level2_bounds >= level1_bounds;
}

// CentroidBound returns N(ca - cb) for raw centroids laid out as Centroid
// returns them ([g, K x ba, A x ba, H x ba] and the same for b with bb
// bands; missing bands count as zero): EmdLowerBound for callers that keep
// centroids apart from their signatures. O(bands), no allocation;
// thread-safe.
double CentroidBound(const double* ca, int ba, const double* cb, int bb);

namespace internal {

// CentroidNorm returns N(x - y) for two centroids given by accessors:
// x(-1, 0) is row 0 (W1 G'), x(block, d) band d of block 0, 1, 2 (K, A,
// H) for d < ba, and likewise y with bb bands; bands one side lacks count
// as zero. The one arithmetic behind every form of the centroid bound
// (EmdLowerBound, CentroidBound, CentroidTable), so that they agree bit
// for bit. Per-block accessors keep the block out of the inner loops
// (a per-row one would divide per value).
template <typename X, typename Y>
double CentroidNorm(const X& x, int ba, const Y& y, int bb) {
  const int common = ba < bb ? ba : bb;
  double result = std::abs(x(-1, 0) - y(-1, 0));
  for (int block = 0; block < 3; ++block) {
    double s = 0.0;
    for (int d = 0; d < common; ++d) {
      const double diff = x(block, d) - y(block, d);
      s += diff * diff;
    }
    for (int d = common; d < ba; ++d) s += x(block, d) * x(block, d);
    for (int d = common; d < bb; ++d) s += y(block, d) * y(block, d);
    result += std::sqrt(s);
  }
  return result;
}

}  // namespace internal

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_EMD_H_
