// AVX-512F ground-distance kernels (ground_distance_kernels.h), compiled
// with -mavx512f. Lanes run over 8 consecutive features of b (16 in the
// float32 kernel: the dimension-major layout of PreparedSignature); a's
// coordinates are broadcast. Each lane accumulates its bands in the same
// order as every other variant, so the double matrix equals the AVX2
// one bit for bit and is symmetric under swapping a and b exactly:
// (x - y)^2 and (y - x)^2 are the same double and fma(d, d, s) depends on
// d only through d * d.
#ifdef TPR_HAVE_X86_KERNELS
#include <immintrin.h>

#include <cstddef>

#include "indexer/lib/internal/ground_distance_kernels.h"

namespace tpr::index::internal {
namespace {

inline int Min(int a, int b) { return a < b ? a : b; }

// GCC 12's avx512fintrin.h trips -Wmaybe-uninitialized on its own
// _mm512_undefined_pd (a known false positive).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"

// Avx512Blocks computes the columns of blocks k0 .. k0 + B - 1 of the
// matrix from b's widened coordinates (`rows` rows per block): each
// broadcast coordinate of a serves B blocks, and the 3 B accumulators are
// independent chains. Every lane accumulates its bands in the one-block
// order, so the values do not depend on B. Returns max(mx, what it wrote).
template <int B>
inline __m512d Avx512Blocks(const KernelCoords& a, const double* wide,
                            size_t rows, int k0, double* out, int out_stride,
                            __m512d mx) {
  const int bands = a.bands;
  const size_t as = static_cast<size_t>(a.size);
  const float* ac = a.coords;
  const double* blk[B];
  for (int b = 0; b < B; ++b) {
    blk[b] = wide + static_cast<size_t>(k0 + b) * rows * 8;
  }
  for (int i = 0; i < a.size; ++i) {
    __m512d k[B], ar[B], h[B];
    for (int b = 0; b < B; ++b) {
      k[b] = _mm512_setzero_pd();
      ar[b] = _mm512_setzero_pd();
      h[b] = _mm512_setzero_pd();
    }
    for (int d = 0; d < bands; ++d) {
      const size_t rk = static_cast<size_t>(1 + d);
      const size_t ra = rk + static_cast<size_t>(bands);
      const size_t rh = ra + static_cast<size_t>(bands);
      const __m512d xk = _mm512_set1_pd(ac[rk * as + i]);
      const __m512d xa = _mm512_set1_pd(ac[ra * as + i]);
      const __m512d xh = _mm512_set1_pd(ac[rh * as + i]);
      for (int b = 0; b < B; ++b) {
        __m512d t;
        t = _mm512_sub_pd(xk, _mm512_loadu_pd(blk[b] + rk * 8));
        k[b] = _mm512_fmadd_pd(t, t, k[b]);
        t = _mm512_sub_pd(xa, _mm512_loadu_pd(blk[b] + ra * 8));
        ar[b] = _mm512_fmadd_pd(t, t, ar[b]);
        t = _mm512_sub_pd(xh, _mm512_loadu_pd(blk[b] + rh * 8));
        h[b] = _mm512_fmadd_pd(t, t, h[b]);
      }
    }
    const __m512d xg = _mm512_set1_pd(ac[i]);
    double* row = out + static_cast<size_t>(i) * out_stride + 8 * k0;
    for (int b = 0; b < B; ++b) {
      __m512d g = _mm512_abs_pd(_mm512_sub_pd(xg, _mm512_loadu_pd(blk[b])));
      g = _mm512_add_pd(_mm512_add_pd(_mm512_add_pd(g, _mm512_sqrt_pd(k[b])),
                                      _mm512_sqrt_pd(ar[b])),
                        _mm512_sqrt_pd(h[b]));
      _mm512_storeu_pd(row + 8 * b, g);
      mx = _mm512_max_pd(mx, g);
    }
  }
  return mx;
}

// WidenAvx512 writes b's float32 coordinates widened to double (exact) to
// `buffer`, block by block: columns 8k .. 8k + 7 of row r at
// [(k rows + r) 8], columns at or past b.size as 0, reading b's
// coordinates once in memory order (so that a signature not in cache
// streams in behind the hardware prefetcher), with one masked load and one
// conversion per block row: a scalar tail for the last, partial block
// (features 24 .. 29 at 30) was about a sixth of the matrix's time at
// n = m = 30 (perf). Masked-off lanes are not read, so nothing past b's
// block is touched.
void WidenAvx512(const KernelCoords& b, double* buffer) {
  const size_t rows = static_cast<size_t>(1 + 3 * b.bands);
  const size_t n = static_cast<size_t>(b.size);
  const size_t blocks = (n + 7) / 8;
  const float* in = b.coords;
  const __mmask16 tail =
      static_cast<__mmask16>((1u << (n - 8 * (blocks - 1))) - 1);
  for (size_t r = 0; r < rows; ++r, in += n) {
    for (size_t k = 0; k + 1 < blocks; ++k) {
      _mm512_storeu_pd(buffer + (k * rows + r) * 8,
                       _mm512_cvtps_pd(_mm256_loadu_ps(in + 8 * k)));
    }
    const size_t k = blocks - 1;
    const __m512 x = _mm512_maskz_loadu_ps(tail, in + 8 * k);
    _mm512_storeu_pd(buffer + (k * rows + r) * 8,
                     _mm512_cvtps_pd(_mm512_castps512_ps256(x)));
  }
}

double MatrixAvx512(const KernelCoords& a, const KernelCoords& b, double* wide,
                    double* out, int out_stride) {
  WidenAvx512(b, wide);
  const size_t rows = static_cast<size_t>(1 + 3 * b.bands);
  const int blocks = (b.size + 7) / 8;
  __m512d mx = _mm512_setzero_pd();
  int k = 0;
  for (; k + 4 <= blocks; k += 4) {
    mx = Avx512Blocks<4>(a, wide, rows, k, out, out_stride, mx);
  }
  if (k + 2 <= blocks) {
    mx = Avx512Blocks<2>(a, wide, rows, k, out, out_stride, mx);
    k += 2;
  }
  if (k < blocks) mx = Avx512Blocks<1>(a, wide, rows, k, out, out_stride, mx);
  return _mm512_reduce_max_pd(mx);
}

// Avx512Rows32 computes rows i0 .. i0 + I - 1 of the float32 matrix, all
// of b's 16-feature blocks: per block, each row of b's coordinates is one
// masked load straight from the stored float32 values (no widening; lanes
// past b.size read as 0), shared by the I rows of a, whose 3 I
// accumulators are independent chains.
template <int I>
inline void Avx512Rows32(const KernelCoords& a, const KernelCoords& b, int i0,
                         float* out, int out_stride) {
  const int bands = a.bands;
  const size_t as = static_cast<size_t>(a.size);
  const size_t bs = static_cast<size_t>(b.size);
  const float* ac = a.coords + i0;
  for (int j0 = 0; j0 < b.size; j0 += 16) {
    const int lanes = Min(16, b.size - j0);
    const __mmask16 mask = static_cast<__mmask16>((1u << lanes) - 1u);
    const float* bc = b.coords + j0;
    __m512 k[I], ar[I], h[I];
    for (int r = 0; r < I; ++r) {
      k[r] = _mm512_setzero_ps();
      ar[r] = _mm512_setzero_ps();
      h[r] = _mm512_setzero_ps();
    }
    for (int d = 0; d < bands; ++d) {
      const size_t rk = static_cast<size_t>(1 + d);
      const size_t ra = rk + static_cast<size_t>(bands);
      const size_t rh = ra + static_cast<size_t>(bands);
      const __m512 yk = _mm512_maskz_loadu_ps(mask, bc + rk * bs);
      const __m512 ya = _mm512_maskz_loadu_ps(mask, bc + ra * bs);
      const __m512 yh = _mm512_maskz_loadu_ps(mask, bc + rh * bs);
      for (int r = 0; r < I; ++r) {
        __m512 t;
        t = _mm512_sub_ps(_mm512_set1_ps(ac[rk * as + r]), yk);
        k[r] = _mm512_fmadd_ps(t, t, k[r]);
        t = _mm512_sub_ps(_mm512_set1_ps(ac[ra * as + r]), ya);
        ar[r] = _mm512_fmadd_ps(t, t, ar[r]);
        t = _mm512_sub_ps(_mm512_set1_ps(ac[rh * as + r]), yh);
        h[r] = _mm512_fmadd_ps(t, t, h[r]);
      }
    }
    const __m512 yg = _mm512_maskz_loadu_ps(mask, bc);
    for (int r = 0; r < I; ++r) {
      __m512 g = _mm512_abs_ps(_mm512_sub_ps(_mm512_set1_ps(ac[r]), yg));
      g = _mm512_add_ps(_mm512_add_ps(_mm512_add_ps(g, _mm512_sqrt_ps(k[r])),
                                      _mm512_sqrt_ps(ar[r])),
                        _mm512_sqrt_ps(h[r]));
      _mm512_storeu_ps(out + static_cast<size_t>(i0 + r) * out_stride + j0, g);
    }
  }
}

void Matrix32Avx512(const KernelCoords& a, const KernelCoords& b,
                    int /*stride32*/, float* out, int out_stride) {
  int i = 0;
  for (; i + 4 <= a.size; i += 4) Avx512Rows32<4>(a, b, i, out, out_stride);
  for (; i < a.size; ++i) Avx512Rows32<1>(a, b, i, out, out_stride);
}
#pragma GCC diagnostic pop

constexpr MatrixKernels kAvx512Kernels = {MatrixAvx512, Matrix32Avx512};

}  // namespace

const MatrixKernels* MatrixKernelsAvx512Table() { return &kAvx512Kernels; }

}  // namespace tpr::index::internal
#endif  // TPR_HAVE_X86_KERNELS
