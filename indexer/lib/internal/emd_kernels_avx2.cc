// AVX2 EMD kernels (emd_kernels.h), compiled with -mavx2 -mfma -mpopcnt:
// the AVX-512F kernels' shapes on 4-lane registers, the same values as the
// scalar ones bit for bit (each lane does the scalar lane's operations in
// its order; minima and comparisons round nothing). Where AVX-512 has a
// mask register, these keep a mask vector (compare results, blendv) and
// gather bits with movemask.
#ifdef TPR_HAVE_X86_KERNELS
#include <immintrin.h>

#include <cstddef>

#include "indexer/lib/internal/emd_kernels.h"

namespace tpr::index::internal {
namespace {

constexpr double kInf = __builtin_inf();

inline int Min(int a, int b) { return a < b ? a : b; }
inline int Max(int a, int b) { return a < b ? b : a; }

inline uint64_t ClosedWord(uint64_t closed_lo, const uint64_t* closed, int j) {
  return j < 64 ? closed_lo : closed[j >> 6];
}

// Blocks of 8 columns (two registers each) are priced B at a time, so
// that 2 B independent compare-and-blend chains overlap (one register is
// latency-bound on its chain of compare and blend).
template <int B>
inline int CollectBlocksAvx2(const double* cost, int cs, int n, const double* u,
                             const double* v, double tol, int j0, int* cand_i,
                             int* cand_j, int count) {
  constexpr int V = 2 * B;
  const __m256d one = _mm256_set1_pd(1.0);
  __m256d vj[V], mn[V], arg[V];
  for (int b = 0; b < V; ++b) {
    vj[b] = _mm256_loadu_pd(v + j0 + 4 * b);
    mn[b] = _mm256_set1_pd(-tol);
    arg[b] = _mm256_set1_pd(-1.0);
  }
  __m256d idx = _mm256_setzero_pd();
  for (int i = 0; i < n; ++i) {
    const double* row = cost + static_cast<size_t>(i) * cs + j0;
    const __m256d ui = _mm256_set1_pd(u[i]);
    for (int b = 0; b < V; ++b) {
      const __m256d r =
          _mm256_sub_pd(_mm256_add_pd(_mm256_loadu_pd(row + 4 * b), ui), vj[b]);
      const __m256d lt = _mm256_cmp_pd(r, mn[b], _CMP_LT_OQ);
      // min(r, mn) is r < mn ? r : mn, the blend on lt, in one uop.
      mn[b] = _mm256_min_pd(r, mn[b]);
      arg[b] = _mm256_blendv_pd(arg[b], idx, lt);
    }
    idx = _mm256_add_pd(idx, one);
  }
  for (int b = 0; b < V; ++b) {
    alignas(32) double rows[4];
    _mm256_store_pd(rows, arg[b]);
    for (int l = 0; l < 4; ++l) {
      cand_i[count] = static_cast<int>(rows[l]);
      cand_j[count] = j0 + 4 * b + l;
      count += rows[l] >= 0.0;
    }
  }
  return count;
}

int CollectAvx2(const double* cost, int cs, int n, const double* u,
                const double* v, double tol, int* cand_i, int* cand_j) {
  int count = 0;
  int j0 = 0;
  for (; j0 + 16 <= cs; j0 += 16) {
    count =
        CollectBlocksAvx2<2>(cost, cs, n, u, v, tol, j0, cand_i, cand_j, count);
  }
  if (j0 < cs) {
    count =
        CollectBlocksAvx2<1>(cost, cs, n, u, v, tol, j0, cand_i, cand_j, count);
  }
  return count;
}

// Open lanes j .. j + 3 (j a multiple of 4) as a mask vector (all ones
// where open), from the closed set's bits.
inline __m256d OpenMask(uint64_t closed_lo, const uint64_t* closed, int j) {
  const __m256i bits = _mm256_set1_epi64x(
      static_cast<long long>(ClosedWord(closed_lo, closed, j) >> (j & 63)));
  const __m256i lane = _mm256_setr_epi64x(1, 2, 4, 8);
  return _mm256_castsi256_pd(
      _mm256_cmpeq_epi64(_mm256_and_si256(bits, lane), _mm256_setzero_si256()));
}

// row + offset where open, +inf where closed (as OpenValues of the AVX-512
// kernel: the open lanes' sums are the same doubles).
inline __m256d OpenValues(const double* row, const double* offset,
                          __m256d open) {
  return _mm256_blendv_pd(
      _mm256_set1_pd(kInf),
      _mm256_add_pd(_mm256_loadu_pd(row), _mm256_loadu_pd(offset)), open);
}

inline __m256d Values(const double* row, const double* offset,
                      uint64_t closed_lo, const uint64_t* closed, int j) {
  return OpenValues(row + j, offset + j, OpenMask(closed_lo, closed, j));
}

// The AVX-512 kernel's method: the minimum first (two chains of 8 columns
// each, then two in-register swaps), then the first open column equal to
// it, from movemask bits.
int RowArgMinAvx2(const double* row, const double* offset, uint64_t closed_lo,
                  const uint64_t* closed, int cs) {
  __m256d m0 = Values(row, offset, closed_lo, closed, 0);
  __m256d m1 = Values(row, offset, closed_lo, closed, 4);
  for (int j0 = 8; j0 < cs; j0 += 8) {
    m0 = _mm256_min_pd(m0, Values(row, offset, closed_lo, closed, j0));
    m1 = _mm256_min_pd(m1, Values(row, offset, closed_lo, closed, j0 + 4));
  }
  __m256d mn = _mm256_min_pd(m0, m1);
  mn = _mm256_min_pd(mn, _mm256_permute2f128_pd(mn, mn, 0x01));
  mn = _mm256_min_pd(mn, _mm256_permute_pd(mn, 0x5));
  for (int g = 0; g < cs; g += 64) {
    const int end = Min(cs, g + 64);
    uint64_t bits = 0;
    for (int j = g; j < end; j += 4) {
      const __m256d open = OpenMask(closed_lo, closed, j);
      const __m256d eq = _mm256_and_pd(
          open,
          _mm256_cmp_pd(OpenValues(row + j, offset + j, open), mn, _CMP_EQ_OQ));
      bits |= static_cast<uint64_t>(_mm256_movemask_pd(eq)) << (j - g);
    }
    if (bits != 0) return g + __builtin_ctzll(bits);
  }
  return 0;  // not reached: some column is open, so equals the minimum
}

// One chain per 4 columns, rows in order.
void ColumnMinAvx2(const double* cost, int cs, int n, double* out) {
  for (int j0 = 0; j0 < cs; j0 += 8) {
    __m256d lo = _mm256_loadu_pd(cost + j0);
    __m256d hi = _mm256_loadu_pd(cost + j0 + 4);
    for (int i = 1; i < n; ++i) {
      const double* row = cost + static_cast<size_t>(i) * cs + j0;
      lo = _mm256_min_pd(lo, _mm256_loadu_pd(row));
      hi = _mm256_min_pd(hi, _mm256_loadu_pd(row + 4));
    }
    _mm256_storeu_pd(out + j0, lo);
    _mm256_storeu_pd(out + j0 + 4, hi);
  }
}

// Four comparisons per instruction pair, gathered by movemask and counted
// by popcount; the last, partial block is a masked load (lanes past n
// neither read nor counted).
void RankOrderAvx2(const double* w, int n, int* order) {
  for (int i = 0; i < n; ++i) {
    const __m256d wi = _mm256_set1_pd(w[i]);
    int rank = 0;
    for (int k0 = 0; k0 < n; k0 += 4) {
      const int valid = Min(n - k0, 4);
      const unsigned in = (1u << valid) - 1u;
      const int below = Min(Max(i - k0, 0), 4);  // lanes k < i
      const unsigned lower = (1u << below) - 1u;
      const __m256i load = _mm256_cmpgt_epi64(_mm256_set1_epi64x(valid),
                                              _mm256_setr_epi64x(0, 1, 2, 3));
      const __m256d wk = _mm256_maskload_pd(w + k0, load);
      const unsigned lt = static_cast<unsigned>(
          _mm256_movemask_pd(_mm256_cmp_pd(wk, wi, _CMP_LT_OQ)));
      const unsigned eq = static_cast<unsigned>(
          _mm256_movemask_pd(_mm256_cmp_pd(wk, wi, _CMP_EQ_OQ)));
      rank += __builtin_popcount((lt & in) | (eq & lower));
    }
    order[rank] = i;
  }
}

constexpr EmdKernels kAvx2Kernels = {CollectAvx2, RowArgMinAvx2, ColumnMinAvx2,
                                     RankOrderAvx2};

}  // namespace

const EmdKernels* EmdKernelsAvx2Table() { return &kAvx2Kernels; }

}  // namespace tpr::index::internal
#endif  // TPR_HAVE_X86_KERNELS
