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

// ClosedBits walks the closed set 4 columns at a time from column 0: the
// current 64-column word broadcast once, and a running vector of the 4
// lanes' bits in it, so that each step costs a shift, an and and a
// compare.
class ClosedBits {
 public:
  ClosedBits(uint64_t closed_lo, const uint64_t* closed)
      : closed_(closed),
        word_(_mm256_set1_epi64x(static_cast<long long>(closed_lo))),
        bit_(_mm256_setr_epi64x(1, 2, 4, 8)) {}
  // Open lanes of columns j .. j + 3, j = 4 x (the number of calls before),
  // as a mask vector (all ones where open).
  // The next word is read only when its first column is asked for.
  __m256d Next() {
    if (j_ > 0 && (j_ & 63) == 0) {
      word_ = _mm256_set1_epi64x(static_cast<long long>(closed_[j_ >> 6]));
      bit_ = _mm256_setr_epi64x(1, 2, 4, 8);
    }
    const __m256d open = _mm256_castsi256_pd(_mm256_cmpeq_epi64(
        _mm256_and_si256(word_, bit_), _mm256_setzero_si256()));
    j_ += 4;
    bit_ = _mm256_slli_epi64(bit_, 4);
    return open;
  }

 private:
  const uint64_t* closed_;
  __m256i word_;
  __m256i bit_;
  int j_ = 0;
};

// row + offset where open, +inf where closed (as OpenValues of the AVX-512
// kernel: the open lanes' sums are the same doubles).
inline __m256d OpenValues(const double* row, const double* offset,
                          __m256d open) {
  return _mm256_blendv_pd(
      _mm256_set1_pd(kInf),
      _mm256_add_pd(_mm256_loadu_pd(row), _mm256_loadu_pd(offset)), open);
}

// The AVX-512 kernel's method: the minimum first (two chains of 4
// columns, then two in-register swaps), then the first open column equal
// to it, from movemask bits.
int RowArgMinAvx2(const double* row, const double* offset, uint64_t closed_lo,
                  const uint64_t* closed, int cs) {
  ClosedBits walk(closed_lo, closed);
  __m256d m0 = OpenValues(row, offset, walk.Next());
  __m256d m1 = OpenValues(row + 4, offset + 4, walk.Next());
  for (int j0 = 8; j0 < cs; j0 += 8) {
    m0 = _mm256_min_pd(m0, OpenValues(row + j0, offset + j0, walk.Next()));
    m1 = _mm256_min_pd(m1,
                       OpenValues(row + j0 + 4, offset + j0 + 4, walk.Next()));
  }
  __m256d mn = _mm256_min_pd(m0, m1);
  mn = _mm256_min_pd(mn, _mm256_permute2f128_pd(mn, mn, 0x01));
  mn = _mm256_min_pd(mn, _mm256_permute_pd(mn, 0x5));
  ClosedBits again(closed_lo, closed);
  for (int g = 0; g < cs; g += 64) {
    const int end = Min(cs, g + 64);
    uint64_t bits = 0;
    for (int j = g; j < end; j += 4) {
      const __m256d open = again.Next();
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

// Four comparisons per instruction pair, counted in the lanes (a compare
// is -1 where true) and summed once per i. w is copied once into a buffer
// padded with +inf, which is neither below nor equal to any w[i], so no
// lane needs masking; "k < i" is a compare of lane indices.
void RankOrderAvx2(const double* w, int n, int* order) {
  constexpr int kMaxN = 256;  // kMaxFeatures (200) rounded up
  alignas(32) double padded[kMaxN + 4];
  for (int k = 0; k < n; ++k) padded[k] = w[k];
  for (int k = n; k < n + 4; ++k) padded[k] = kInf;
  const __m256i step = _mm256_set1_epi64x(4);
  for (int i = 0; i < n; ++i) {
    const __m256d wi = _mm256_set1_pd(w[i]);
    const __m256i iv = _mm256_set1_epi64x(i);
    __m256i kv = _mm256_setr_epi64x(0, 1, 2, 3);
    __m256i count = _mm256_setzero_si256();
    for (int k0 = 0; k0 < n; k0 += 4) {
      const __m256d wk = _mm256_load_pd(padded + k0);
      const __m256d lt = _mm256_cmp_pd(wk, wi, _CMP_LT_OQ);
      const __m256d eq =
          _mm256_and_pd(_mm256_cmp_pd(wk, wi, _CMP_EQ_OQ),
                        _mm256_castsi256_pd(_mm256_cmpgt_epi64(iv, kv)));
      count =
          _mm256_sub_epi64(count, _mm256_castpd_si256(_mm256_or_pd(lt, eq)));
      kv = _mm256_add_epi64(kv, step);
    }
    const __m128i c2 = _mm_add_epi64(_mm256_castsi256_si128(count),
                                     _mm256_extracti128_si256(count, 1));
    order[_mm_cvtsi128_si32(c2) + _mm_extract_epi32(c2, 2)] = i;
  }
}

constexpr EmdKernels kAvx2Kernels = {CollectAvx2, RowArgMinAvx2, ColumnMinAvx2,
                                     RankOrderAvx2};

}  // namespace

const EmdKernels* EmdKernelsAvx2Table() { return &kAvx2Kernels; }

}  // namespace tpr::index::internal
#endif  // TPR_HAVE_X86_KERNELS
