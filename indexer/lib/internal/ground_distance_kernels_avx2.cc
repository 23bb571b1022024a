// AVX2 + FMA ground-distance kernels (ground_distance_kernels.h), compiled
// with -mavx2 -mfma: the AVX-512F kernels' arithmetic on 4-lane (double)
// and 8-lane (float32) registers, each lane's operations in the same
// order, so both matrices equal the AVX-512F ones bit for bit.
#ifdef TPR_HAVE_X86_KERNELS
#include <immintrin.h>

#include <cstddef>

#include "indexer/lib/internal/ground_distance_kernels.h"

namespace tpr::index::internal {
namespace {

inline int Min(int a, int b) { return a < b ? a : b; }
inline int Max(int a, int b) { return a < b ? b : a; }

// Lanes l < `lanes` of 8 (0 <= lanes <= 8) as a maskload mask.
inline __m256i FirstLanes(int lanes) {
  return _mm256_cmpgt_epi32(_mm256_set1_epi32(lanes),
                            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
}

// WidenAvx2 is WidenAvx512 (same layout, same values): b's coordinates
// widened to double block by block, columns 8k .. 8k + 7 of row r at
// [(k rows + r) 8], columns at or past b.size as 0; the last, partial
// block of a row is one masked load (lanes past b.size not read).
void WidenAvx2(const KernelCoords& b, double* buffer) {
  const size_t rows = static_cast<size_t>(1 + 3 * b.bands);
  const size_t n = static_cast<size_t>(b.size);
  const size_t blocks = (n + 7) / 8;
  const float* in = b.coords;
  const __m256i tail = FirstLanes(static_cast<int>(n - 8 * (blocks - 1)));
  for (size_t r = 0; r < rows; ++r, in += n) {
    for (size_t k = 0; k + 1 < blocks; ++k) {
      double* out = buffer + (k * rows + r) * 8;
      _mm256_storeu_pd(out, _mm256_cvtps_pd(_mm_loadu_ps(in + 8 * k)));
      _mm256_storeu_pd(out + 4, _mm256_cvtps_pd(_mm_loadu_ps(in + 8 * k + 4)));
    }
    const size_t k = blocks - 1;
    double* out = buffer + (k * rows + r) * 8;
    const __m256 x = _mm256_maskload_ps(in + 8 * k, tail);
    _mm256_storeu_pd(out, _mm256_cvtps_pd(_mm256_castps256_ps128(x)));
    _mm256_storeu_pd(out + 4, _mm256_cvtps_pd(_mm256_extractf128_ps(x, 1)));
  }
}

// Avx2Blocks computes the columns of blocks k0 .. k0 + B - 1 (8 columns,
// two registers each) of the matrix from b's widened coordinates (`rows`
// rows per block), as Avx512Blocks does: each broadcast coordinate of a
// serves 2 B registers, whose 6 B accumulators are independent chains,
// every lane in the one order. Returns max(mx, what it wrote).
template <int B>
inline __m256d Avx2Blocks(const KernelCoords& a, const double* wide,
                          size_t rows, int k0, double* out, int out_stride,
                          __m256d mx) {
  constexpr int V = 2 * B;
  const int bands = a.bands;
  const size_t as = static_cast<size_t>(a.size);
  const float* ac = a.coords;
  const __m256d sign = _mm256_set1_pd(-0.0);
  const double* blk[V];
  for (int v = 0; v < V; ++v) {
    blk[v] = wide + static_cast<size_t>(k0 + v / 2) * rows * 8 + 4 * (v % 2);
  }
  for (int i = 0; i < a.size; ++i) {
    __m256d k[V], ar[V], h[V];
    for (int v = 0; v < V; ++v) {
      k[v] = _mm256_setzero_pd();
      ar[v] = _mm256_setzero_pd();
      h[v] = _mm256_setzero_pd();
    }
    for (int d = 0; d < bands; ++d) {
      const size_t rk = static_cast<size_t>(1 + d);
      const size_t ra = rk + static_cast<size_t>(bands);
      const size_t rh = ra + static_cast<size_t>(bands);
      const __m256d xk = _mm256_set1_pd(ac[rk * as + i]);
      const __m256d xa = _mm256_set1_pd(ac[ra * as + i]);
      const __m256d xh = _mm256_set1_pd(ac[rh * as + i]);
      for (int v = 0; v < V; ++v) {
        __m256d t;
        t = _mm256_sub_pd(xk, _mm256_loadu_pd(blk[v] + rk * 8));
        k[v] = _mm256_fmadd_pd(t, t, k[v]);
        t = _mm256_sub_pd(xa, _mm256_loadu_pd(blk[v] + ra * 8));
        ar[v] = _mm256_fmadd_pd(t, t, ar[v]);
        t = _mm256_sub_pd(xh, _mm256_loadu_pd(blk[v] + rh * 8));
        h[v] = _mm256_fmadd_pd(t, t, h[v]);
      }
    }
    const __m256d xg = _mm256_set1_pd(ac[i]);
    double* row = out + static_cast<size_t>(i) * out_stride + 8 * k0;
    for (int v = 0; v < V; ++v) {
      __m256d g =
          _mm256_andnot_pd(sign, _mm256_sub_pd(xg, _mm256_loadu_pd(blk[v])));
      g = _mm256_add_pd(_mm256_add_pd(_mm256_add_pd(g, _mm256_sqrt_pd(k[v])),
                                      _mm256_sqrt_pd(ar[v])),
                        _mm256_sqrt_pd(h[v]));
      _mm256_storeu_pd(row + 4 * v, g);
      mx = _mm256_max_pd(mx, g);
    }
  }
  return mx;
}

// Two blocks (16 columns, 12 accumulators) at a time, then the odd one.
double MatrixAvx2(const KernelCoords& a, const KernelCoords& b, double* wide,
                  double* out, int out_stride) {
  WidenAvx2(b, wide);
  const size_t rows = static_cast<size_t>(1 + 3 * b.bands);
  const int blocks = (b.size + 7) / 8;
  __m256d mx = _mm256_setzero_pd();
  int k = 0;
  for (; k + 2 <= blocks; k += 2) {
    mx = Avx2Blocks<2>(a, wide, rows, k, out, out_stride, mx);
  }
  if (k < blocks) mx = Avx2Blocks<1>(a, wide, rows, k, out, out_stride, mx);
  mx = _mm256_max_pd(mx, _mm256_permute2f128_pd(mx, mx, 0x01));
  mx = _mm256_max_pd(mx, _mm256_permute_pd(mx, 0x5));
  return _mm256_cvtsd_f64(mx);
}

// Avx2Rows32 computes rows i0 .. i0 + I - 1 of the float32 matrix, all of
// its 8-column blocks up to stride32: per block, each row of b's
// coordinates is one load straight from the stored float32 values (masked
// for the last, partial block: lanes past b.size read as 0, as in the
// AVX-512F kernel's 16-lane loads; blocks wholly past b.size read
// nothing), shared by the I rows of a, whose 3 I accumulators are
// independent chains.
template <int I>
inline void Avx2Rows32(const KernelCoords& a, const KernelCoords& b,
                       int stride32, int i0, float* out, int out_stride) {
  const int bands = a.bands;
  const size_t as = static_cast<size_t>(a.size);
  const size_t bs = static_cast<size_t>(b.size);
  const float* ac = a.coords + i0;
  const __m256 sign = _mm256_set1_ps(-0.0f);
  for (int j0 = 0; j0 < stride32; j0 += 8) {
    const int lanes = Max(0, Min(8, b.size - j0));
    const __m256i mask = FirstLanes(lanes);
    // Blocks wholly past b.size point at b's first block, all lanes off.
    const float* bc = b.coords + (lanes > 0 ? j0 : 0);
    auto load = [&](const float* p) {
      return lanes == 8 ? _mm256_loadu_ps(p) : _mm256_maskload_ps(p, mask);
    };
    __m256 k[I], ar[I], h[I];
    for (int r = 0; r < I; ++r) {
      k[r] = _mm256_setzero_ps();
      ar[r] = _mm256_setzero_ps();
      h[r] = _mm256_setzero_ps();
    }
    for (int d = 0; d < bands; ++d) {
      const size_t rk = static_cast<size_t>(1 + d);
      const size_t ra = rk + static_cast<size_t>(bands);
      const size_t rh = ra + static_cast<size_t>(bands);
      const __m256 yk = load(bc + rk * bs);
      const __m256 ya = load(bc + ra * bs);
      const __m256 yh = load(bc + rh * bs);
      for (int r = 0; r < I; ++r) {
        __m256 t;
        t = _mm256_sub_ps(_mm256_set1_ps(ac[rk * as + r]), yk);
        k[r] = _mm256_fmadd_ps(t, t, k[r]);
        t = _mm256_sub_ps(_mm256_set1_ps(ac[ra * as + r]), ya);
        ar[r] = _mm256_fmadd_ps(t, t, ar[r]);
        t = _mm256_sub_ps(_mm256_set1_ps(ac[rh * as + r]), yh);
        h[r] = _mm256_fmadd_ps(t, t, h[r]);
      }
    }
    const __m256 yg = load(bc);
    for (int r = 0; r < I; ++r) {
      __m256 g =
          _mm256_andnot_ps(sign, _mm256_sub_ps(_mm256_set1_ps(ac[r]), yg));
      g = _mm256_add_ps(_mm256_add_ps(_mm256_add_ps(g, _mm256_sqrt_ps(k[r])),
                                      _mm256_sqrt_ps(ar[r])),
                        _mm256_sqrt_ps(h[r]));
      _mm256_storeu_ps(out + static_cast<size_t>(i0 + r) * out_stride + j0, g);
    }
  }
}

void Matrix32Avx2(const KernelCoords& a, const KernelCoords& b, int stride32,
                  float* out, int out_stride) {
  int i = 0;
  for (; i + 4 <= a.size; i += 4) {
    Avx2Rows32<4>(a, b, stride32, i, out, out_stride);
  }
  for (; i < a.size; ++i) Avx2Rows32<1>(a, b, stride32, i, out, out_stride);
}

constexpr MatrixKernels kAvx2Kernels = {MatrixAvx2, Matrix32Avx2};

}  // namespace

const MatrixKernels* MatrixKernelsAvx2Table() { return &kAvx2Kernels; }

}  // namespace tpr::index::internal
#endif  // TPR_HAVE_X86_KERNELS
