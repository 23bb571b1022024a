// Ground distance of Eq. 7 and signature preparation. See ground_distance.h
// for the definition of L2norm and why the result is a metric.
#include "indexer/lib/ground_distance.h"

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"

#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

namespace tpr::index {
namespace {

// Rows are padded to a multiple of 8 doubles so that the inner loop of the
// distance kernel runs over whole SIMD registers (2, 4 or 8 lanes) with no
// remainder handling.
constexpr int kLanePad = 8;

int PaddedStride(int n) { return (n + kLanePad - 1) / kLanePad * kLanePad; }

bool AllFinite(const std::vector<double>& v) {
  for (double x : v) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

}  // namespace

absl::Status ValidateOptions(const GroundDistanceOptions& o) {
  const double w[4] = {o.w1, o.w2, o.w3, o.w4};
  double sum = 0.0;
  for (int i = 0; i < 4; ++i) {
    if (!std::isfinite(w[i]) || w[i] < 0.0) {
      return absl::InvalidArgumentError(
          absl::StrCat("ground distance weight w", i + 1, " = ", w[i],
                       " must be finite and >= 0"));
    }
    sum += w[i];
  }
  if (std::abs(sum - 1.0) > 1e-6) {
    return absl::InvalidArgumentError(absl::StrCat(
        "ground distance weights w1..w4 sum to ", sum, ", must sum to 1"));
  }
  const double s[3] = {o.k_scale, o.a_scale, o.h_scale};
  const char* names[3] = {"k_scale", "a_scale", "h_scale"};
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(s[i]) || s[i] <= 0.0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "ground distance ", names[i], " = ", s[i], " must be finite and > 0"));
    }
  }
  return ValidateSpectralOptions(o.spectral);
}

absl::Status ValidateSignature(const Signature& signature) {
  const auto& f = signature.features;
  if (f.empty()) {
    return absl::InvalidArgumentError("signature has no feature");
  }
  if (f.size() > static_cast<size_t>(kMaxFeatures)) {
    return absl::InvalidArgumentError(
        absl::StrCat("signature has ", f.size(), " features, at most ",
                     kMaxFeatures, " are supported"));
  }
  const size_t bands = f[0].curvature.size();
  double sum = 0.0;
  for (size_t i = 0; i < f.size(); ++i) {
    const Feature& x = f[i];
    if (!std::isfinite(x.weight) || x.weight < 0.0) {
      return absl::InvalidArgumentError(
          absl::StrCat("feature ", i, ": weight ", x.weight,
                       " must be finite and >= 0"));
    }
    if (!std::isfinite(x.integral_geodesic)) {
      return absl::InvalidArgumentError(
          absl::StrCat("feature ", i, ": integral geodesic is not finite"));
    }
    if (x.curvature.size() != bands || x.area.size() != bands || x.distance.size() != bands) {
      return absl::InvalidArgumentError(absl::StrCat(
          "feature ", i, ": curvature, area, distance have lengths ", x.curvature.size(),
          ", ", x.area.size(), ", ", x.distance.size(), "; expected ", bands,
          " each (the length of feature 0's curvature)"));
    }
    for (const std::vector<double>* band : BandVectors(x)) {
      if (!AllFinite(*band)) {
        return absl::InvalidArgumentError(absl::StrCat(
            "feature ", i, ": a band vector holds a non-finite value"));
      }
    }
    sum += x.weight;
  }
  if (std::abs(sum - 1.0) > 1e-6) {
    return absl::InvalidArgumentError(absl::StrCat(
        "signature weights sum to ", sum, ", must sum to 1 (Eq. 6)"));
  }
  if (signature.spectrum.size() > static_cast<size_t>(kMaxSpectrum)) {
    return absl::InvalidArgumentError(absl::StrCat("spectrum has ", signature.spectrum.size(),
                                                   " values, at most ", kMaxSpectrum,
                                                   " are supported"));
  }
  for (size_t i = 0; i < signature.spectrum.size(); ++i) {
    const double x = signature.spectrum[i];
    if (!std::isfinite(x) || x <= 0.0) {
      return absl::InvalidArgumentError(
          absl::StrCat("spectrum[", i, "] is ", x, "; must be finite and > 0"));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<PreparedSignature> Prepare(const Signature& signature,
                                          const GroundDistanceOptions& options) {
  if (absl::Status s = ValidateOptions(options); !s.ok()) return s;
  if (absl::Status s = ValidateSignature(signature); !s.ok()) return s;
  const auto& f = signature.features;
  static std::atomic<uint64_t> next_serial{1};
  PreparedSignature p;
  p.serial_ = next_serial.fetch_add(1, std::memory_order_relaxed);
  p.size_ = static_cast<int>(f.size());
  p.bands_ = static_cast<int>(f[0].curvature.size());
  p.stride_ = PaddedStride(p.size_);
  const int n = p.size_;
  const int bands = p.bands_;
  const size_t stride = static_cast<size_t>(p.stride_);
  const size_t rows = 1 + 3 * static_cast<size_t>(bands);

  double sum = 0.0;
  for (const Feature& x : f) sum += x.weight;
  p.weights_.resize(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) p.weights_[i] = f[i].weight / sum;

  // phi(U) of ground_distance.h, dimension-major.
  p.coords_.assign(rows * stride, 0.0);
  const double ck = options.w2 * options.k_scale;
  const double ca = options.w3 * options.a_scale;
  const double ch = options.w4 * options.h_scale;
  for (int i = 0; i < n; ++i) {
    const Feature& x = f[i];
    p.coords_[i] = options.w1 * x.integral_geodesic;
    for (int b = 0; b < bands; ++b) {
      p.coords_[(1 + b) * stride + i] = ck * x.curvature[b];
      p.coords_[(1 + bands + b) * stride + i] = ca * x.area[b];
      p.coords_[(1 + 2 * bands + b) * stride + i] = ch * x.distance[b];
    }
  }
  p.centroid_.assign(rows, 0.0);
  for (size_t r = 0; r < rows; ++r) {
    double c = 0.0;
    for (int i = 0; i < n; ++i) c += p.weights_[i] * p.coords_[r * stride + i];
    p.centroid_[r] = c;
  }
  p.spectral_ = SpectralEmbedding(signature.spectrum, options.spectral);
  return p;
}

namespace {

// Squared L2 distance of one band block between feature i of a and feature
// j of b, the shorter vector padded with zeros.
double BlockSquared(const PreparedSignature& a, int i, int a_row0,
                    const PreparedSignature& b, int j, int b_row0) {
  const int common = std::min(a.bands(), b.bands());
  const double* ac = a.coords();
  const double* bc = b.coords();
  const size_t as = static_cast<size_t>(a.stride());
  const size_t bs = static_cast<size_t>(b.stride());
  double s = 0.0;
  for (int d = 0; d < common; ++d) {
    const double diff = ac[(a_row0 + d) * as + i] - bc[(b_row0 + d) * bs + j];
    s += diff * diff;
  }
  for (int d = common; d < a.bands(); ++d) {
    const double x = ac[(a_row0 + d) * as + i];
    s += x * x;
  }
  for (int d = common; d < b.bands(); ++d) {
    const double x = bc[(b_row0 + d) * bs + j];
    s += x * x;
  }
  return s;
}

}  // namespace

double GroundDistance(const PreparedSignature& a, int i,
                      const PreparedSignature& b, int j) {
  assert(i >= 0 && i < a.size() && j >= 0 && j < b.size());
  const double g = std::abs(a.coords()[i] - b.coords()[j]);
  const double k = std::sqrt(BlockSquared(a, i, 1, b, j, 1));
  const double ar =
      std::sqrt(BlockSquared(a, i, 1 + a.bands(), b, j, 1 + b.bands()));
  const double h = std::sqrt(
      BlockSquared(a, i, 1 + 2 * a.bands(), b, j, 1 + 2 * b.bands()));
  return ((g + k) + ar) + h;
}

namespace {

// Kernels return the largest entry they wrote (padding included), which the
// EMD uses to scale its optimality tolerance at no extra pass.
using KernelFn = double (*)(const PreparedSignature&, const PreparedSignature&,
                            double*, int);

// Portable kernel, also used when the two signatures have different band
// counts (never the case within one index).
double KernelScalar(const PreparedSignature& a, const PreparedSignature& b,
                    double* out, int out_stride) {
  double mx = 0.0;
  for (int i = 0; i < a.size(); ++i) {
    for (int j = 0; j < b.size(); ++j) {
      const double d = GroundDistance(a, i, b, j);
      out[static_cast<size_t>(i) * out_stride + j] = d;
      mx = std::max(mx, d);
    }
    for (int j = b.size(); j < b.stride(); ++j) {
      out[static_cast<size_t>(i) * out_stride + j] = 0.0;
    }
  }
  return mx;
}

#if defined(__GNUC__) && defined(__x86_64__)
#define TPR_HAVE_X86_KERNELS 1

// Why intrinsics: the build targets baseline x86-64 (SSE2), and GCC does
// not vectorize sqrt without -fno-math-errno; the matrix is about a third
// of an EMD, so it gets hand-written AVX2 and AVX-512 versions chosen once
// at run time. Lanes run over 8 consecutive features of b (the padded,
// dimension-major layout of PreparedSignature); a's coordinates are
// broadcast. Each lane accumulates its bands in the same order, so the
// matrix is symmetric under swapping a and b exactly: (x - y)^2 and
// (y - x)^2 are the same double and fma(d, d, s) depends on d only
// through d * d.
__attribute__((target("avx2,fma"))) double KernelAvx2(
    const PreparedSignature& a, const PreparedSignature& b, double* out,
    int out_stride) {
  const int bands = a.bands();
  const size_t as = static_cast<size_t>(a.stride());
  const size_t bs = static_cast<size_t>(b.stride());
  const double* ac = a.coords();
  const double* bc = b.coords();
  const __m256d sign = _mm256_set1_pd(-0.0);
  __m256d mx = _mm256_setzero_pd();
  for (int i = 0; i < a.size(); ++i) {
    double* row = out + static_cast<size_t>(i) * out_stride;
    for (int j0 = 0; j0 < b.stride(); j0 += 8) {
      __m256d k0 = _mm256_setzero_pd(), k1 = _mm256_setzero_pd();
      __m256d a0 = _mm256_setzero_pd(), a1 = _mm256_setzero_pd();
      __m256d h0 = _mm256_setzero_pd(), h1 = _mm256_setzero_pd();
      for (int d = 0; d < bands; ++d) {
        const size_t rk = static_cast<size_t>(1 + d);
        const size_t ra = rk + static_cast<size_t>(bands);
        const size_t rh = ra + static_cast<size_t>(bands);
        const __m256d xk = _mm256_broadcast_sd(ac + rk * as + i);
        const __m256d xa = _mm256_broadcast_sd(ac + ra * as + i);
        const __m256d xh = _mm256_broadcast_sd(ac + rh * as + i);
        const double* yk = bc + rk * bs + j0;
        const double* ya = bc + ra * bs + j0;
        const double* yh = bc + rh * bs + j0;
        __m256d t;
        t = _mm256_sub_pd(xk, _mm256_loadu_pd(yk));
        k0 = _mm256_fmadd_pd(t, t, k0);
        t = _mm256_sub_pd(xk, _mm256_loadu_pd(yk + 4));
        k1 = _mm256_fmadd_pd(t, t, k1);
        t = _mm256_sub_pd(xa, _mm256_loadu_pd(ya));
        a0 = _mm256_fmadd_pd(t, t, a0);
        t = _mm256_sub_pd(xa, _mm256_loadu_pd(ya + 4));
        a1 = _mm256_fmadd_pd(t, t, a1);
        t = _mm256_sub_pd(xh, _mm256_loadu_pd(yh));
        h0 = _mm256_fmadd_pd(t, t, h0);
        t = _mm256_sub_pd(xh, _mm256_loadu_pd(yh + 4));
        h1 = _mm256_fmadd_pd(t, t, h1);
      }
      const __m256d xg = _mm256_broadcast_sd(ac + i);
      __m256d g0 = _mm256_andnot_pd(sign, _mm256_sub_pd(xg, _mm256_loadu_pd(bc + j0)));
      __m256d g1 =
          _mm256_andnot_pd(sign, _mm256_sub_pd(xg, _mm256_loadu_pd(bc + j0 + 4)));
      g0 = _mm256_add_pd(_mm256_add_pd(_mm256_add_pd(g0, _mm256_sqrt_pd(k0)),
                                       _mm256_sqrt_pd(a0)),
                         _mm256_sqrt_pd(h0));
      g1 = _mm256_add_pd(_mm256_add_pd(_mm256_add_pd(g1, _mm256_sqrt_pd(k1)),
                                       _mm256_sqrt_pd(a1)),
                         _mm256_sqrt_pd(h1));
      _mm256_storeu_pd(row + j0, g0);
      _mm256_storeu_pd(row + j0 + 4, g1);
      mx = _mm256_max_pd(mx, _mm256_max_pd(g0, g1));
    }
  }
  alignas(32) double lanes[4];
  _mm256_store_pd(lanes, mx);
  return std::max(std::max(lanes[0], lanes[1]), std::max(lanes[2], lanes[3]));
}

// GCC 12's avx512fintrin.h trips -Wmaybe-uninitialized on its own
// _mm512_undefined_pd (a known false positive).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
__attribute__((target("avx512f"))) double KernelAvx512(
    const PreparedSignature& a, const PreparedSignature& b, double* out,
    int out_stride) {
  const int bands = a.bands();
  const size_t as = static_cast<size_t>(a.stride());
  const size_t bs = static_cast<size_t>(b.stride());
  const double* ac = a.coords();
  const double* bc = b.coords();
  __m512d mx = _mm512_setzero_pd();
  for (int i = 0; i < a.size(); ++i) {
    double* row = out + static_cast<size_t>(i) * out_stride;
    for (int j0 = 0; j0 < b.stride(); j0 += 8) {
      __m512d k = _mm512_setzero_pd();
      __m512d ar = _mm512_setzero_pd();
      __m512d h = _mm512_setzero_pd();
      for (int d = 0; d < bands; ++d) {
        const size_t rk = static_cast<size_t>(1 + d);
        const size_t ra = rk + static_cast<size_t>(bands);
        const size_t rh = ra + static_cast<size_t>(bands);
        __m512d t;
        t = _mm512_sub_pd(_mm512_set1_pd(ac[rk * as + i]),
                          _mm512_loadu_pd(bc + rk * bs + j0));
        k = _mm512_fmadd_pd(t, t, k);
        t = _mm512_sub_pd(_mm512_set1_pd(ac[ra * as + i]),
                          _mm512_loadu_pd(bc + ra * bs + j0));
        ar = _mm512_fmadd_pd(t, t, ar);
        t = _mm512_sub_pd(_mm512_set1_pd(ac[rh * as + i]),
                          _mm512_loadu_pd(bc + rh * bs + j0));
        h = _mm512_fmadd_pd(t, t, h);
      }
      __m512d g = _mm512_abs_pd(
          _mm512_sub_pd(_mm512_set1_pd(ac[i]), _mm512_loadu_pd(bc + j0)));
      g = _mm512_add_pd(_mm512_add_pd(_mm512_add_pd(g, _mm512_sqrt_pd(k)),
                                      _mm512_sqrt_pd(ar)),
                        _mm512_sqrt_pd(h));
      _mm512_storeu_pd(row + j0, g);
      mx = _mm512_max_pd(mx, g);
    }
  }
  return _mm512_reduce_max_pd(mx);
}
#pragma GCC diagnostic pop
#endif

KernelFn PickKernel() {
#ifdef TPR_HAVE_X86_KERNELS
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f")) return KernelAvx512;
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) {
    return KernelAvx2;
  }
#endif
  return KernelScalar;
}

}  // namespace

double GroundDistanceMatrix(const PreparedSignature& a,
                            const PreparedSignature& b, double* out,
                            int out_stride) {
  assert(out_stride >= b.stride());
  static const KernelFn kernel = PickKernel();
  if (a.bands() != b.bands()) return KernelScalar(a, b, out, out_stride);
  return kernel(a, b, out, out_stride);
}

}  // namespace tpr::index
