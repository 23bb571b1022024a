// AVX-512F EMD kernels (emd_kernels.h), compiled with -mavx512f: the
// same values as the scalar ones bit for bit.
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

// Why intrinsics: simd.h. GCC 12's avx512fintrin.h trips
// -Wmaybe-uninitialized on its own _mm512_undefined_pd (a known false
// positive).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
// Blocks of 8 columns are priced B at a time, so that B independent
// compare-and-blend chains overlap (one block alone is latency-bound:
// about 4 cycles per row).
template <int B>
inline int CollectBlocksAvx512(const double* cost, int cs, int n,
                               const double* u, const double* v, double tol,
                               int j0, int* cand_i, int* cand_j, int count) {
  const __m512d one = _mm512_set1_pd(1.0);
  __m512d vj[B], mn[B], arg[B];
  for (int b = 0; b < B; ++b) {
    vj[b] = _mm512_loadu_pd(v + j0 + 8 * b);
    mn[b] = _mm512_set1_pd(-tol);
    arg[b] = _mm512_set1_pd(-1.0);
  }
  __m512d idx = _mm512_setzero_pd();
  for (int i = 0; i < n; ++i) {
    const double* row = cost + static_cast<size_t>(i) * cs + j0;
    const __m512d ui = _mm512_set1_pd(u[i]);
    for (int b = 0; b < B; ++b) {
      const __m512d r =
          _mm512_sub_pd(_mm512_add_pd(_mm512_loadu_pd(row + 8 * b), ui), vj[b]);
      const __mmask8 lt = _mm512_cmp_pd_mask(r, mn[b], _CMP_LT_OQ);
      mn[b] = _mm512_mask_blend_pd(lt, mn[b], r);
      arg[b] = _mm512_mask_blend_pd(lt, arg[b], idx);
    }
    idx = _mm512_add_pd(idx, one);
  }
  for (int b = 0; b < B; ++b) {
    alignas(64) double rows[8];
    _mm512_store_pd(rows, arg[b]);
    for (int l = 0; l < 8; ++l) {
      cand_i[count] = static_cast<int>(rows[l]);
      cand_j[count] = j0 + 8 * b + l;
      count += rows[l] >= 0.0;
    }
  }
  return count;
}

int CollectAvx512(const double* cost, int cs, int n, const double* u,
                  const double* v, double tol, int* cand_i, int* cand_j) {
  int count = 0;
  int j0 = 0;
  for (; j0 + 32 <= cs; j0 += 32) {
    count = CollectBlocksAvx512<4>(cost, cs, n, u, v, tol, j0, cand_i, cand_j,
                                   count);
  }
  if (j0 + 16 <= cs) {
    count = CollectBlocksAvx512<2>(cost, cs, n, u, v, tol, j0, cand_i, cand_j,
                                   count);
    j0 += 16;
  }
  if (j0 < cs) {
    count = CollectBlocksAvx512<1>(cost, cs, n, u, v, tol, j0, cand_i, cand_j,
                                   count);
  }
  return count;
}
// Lanes j..j+7 open (j a multiple of 8), and their row + offset values,
// +inf where closed.
inline __mmask8 OpenLanes(uint64_t closed_lo, const uint64_t* closed, int j) {
  return static_cast<__mmask8>(~(ClosedWord(closed_lo, closed, j) >> (j & 63)));
}
inline __m512d OpenValues(const double* row, const double* offset,
                          __mmask8 open) {
  return _mm512_mask_add_pd(_mm512_set1_pd(kInf), open, _mm512_loadu_pd(row),
                            _mm512_loadu_pd(offset));
}

// The minimum first (two independent min chains, then three in-register
// swaps that leave it in every lane), then the first open column equal to
// it (one compare per block, the masks gathered into a bit set): about
// half the latency of a lane-wise argmin followed by two horizontal
// reductions, and the same column (minima round nothing; ties go to the
// first).
int RowArgMinAvx512(const double* row, const double* offset, uint64_t closed_lo,
                    const uint64_t* closed, int cs) {
  const __m512d inf = _mm512_set1_pd(kInf);
  __m512d m0 = OpenValues(row, offset, OpenLanes(closed_lo, closed, 0));
  __m512d m1 = inf;
  int j0 = 8;
  for (; j0 + 16 <= cs; j0 += 16) {
    m0 = _mm512_min_pd(m0, OpenValues(row + j0, offset + j0,
                                      OpenLanes(closed_lo, closed, j0)));
    m1 = _mm512_min_pd(m1, OpenValues(row + j0 + 8, offset + j0 + 8,
                                      OpenLanes(closed_lo, closed, j0 + 8)));
  }
  if (j0 < cs) {
    m1 = _mm512_min_pd(m1, OpenValues(row + j0, offset + j0,
                                      OpenLanes(closed_lo, closed, j0)));
  }
  __m512d mn = _mm512_min_pd(m0, m1);
  mn = _mm512_min_pd(mn, _mm512_shuffle_f64x2(mn, mn, 0x4E));
  mn = _mm512_min_pd(mn, _mm512_permutex_pd(mn, 0x4E));
  mn = _mm512_min_pd(mn, _mm512_permute_pd(mn, 0x55));
  for (int g = 0; g < cs; g += 64) {
    const int end = Min(cs, g + 64);
    uint64_t bits = 0;
    for (int j = g; j < end; j += 8) {
      const __mmask8 open = OpenLanes(closed_lo, closed, j);
      bits |= static_cast<uint64_t>(_mm512_mask_cmp_pd_mask(
                  open, OpenValues(row + j, offset + j, open), mn, _CMP_EQ_OQ))
              << (j - g);
    }
    if (bits != 0) return g + __builtin_ctzll(bits);
  }
  return 0;  // not reached: some column is open, so equals the minimum
}
// One zmm chain per block of 8 columns, rows in order (the SSE2 loop the
// compiler makes of ColumnMinScalar was about 5% of InitialBasis).
void ColumnMinAvx512(const double* cost, int cs, int n, double* out) {
  for (int j0 = 0; j0 < cs; j0 += 8) {
    __m512d mn = _mm512_loadu_pd(cost + j0);
    for (int i = 1; i < n; ++i) {
      mn = _mm512_min_pd(
          mn, _mm512_loadu_pd(cost + static_cast<size_t>(i) * cs + j0));
    }
    _mm512_storeu_pd(out + j0, mn);
  }
}
// Eight comparisons per instruction pair, counted by popcount (the
// compiler's SSE2 code for RankOrderScalar took about 2% of a solve at
// n = 30).
void RankOrderAvx512(const double* w, int n, int* order) {
  for (int i = 0; i < n; ++i) {
    const __m512d wi = _mm512_set1_pd(w[i]);
    int rank = 0;
    for (int k0 = 0; k0 < n; k0 += 8) {
      const int valid = Min(n - k0, 8);
      const __mmask8 in = static_cast<__mmask8>((1u << valid) - 1u);
      const int below = Min(Max(i - k0, 0), 8);  // lanes k < i
      const __mmask8 lower = static_cast<__mmask8>((1u << below) - 1u);
      const __m512d wk = _mm512_maskz_loadu_pd(in, w + k0);
      const __mmask8 lt = _mm512_mask_cmp_pd_mask(in, wk, wi, _CMP_LT_OQ);
      const __mmask8 eq = _mm512_mask_cmp_pd_mask(lower, wk, wi, _CMP_EQ_OQ);
      rank += __builtin_popcount(static_cast<unsigned>(lt | eq));
    }
    order[rank] = i;
  }
}
#pragma GCC diagnostic pop

constexpr EmdKernels kAvx512Kernels = {CollectAvx512, RowArgMinAvx512,
                                       ColumnMinAvx512, RankOrderAvx512};

}  // namespace

const EmdKernels* EmdKernelsAvx512Table() { return &kAvx512Kernels; }

}  // namespace tpr::index::internal
#endif  // TPR_HAVE_X86_KERNELS
