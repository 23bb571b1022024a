// Ground distance of Eq. 7 and signature preparation. See ground_distance.h
// for the definition of L2norm and why the result is a metric.
#include "indexer/lib/ground_distance.h"

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <cstring>
#include <string>

#include "absl/strings/str_cat.h"

#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

namespace tpr::index {
namespace {

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
      return absl::InvalidArgumentError(
          absl::StrCat("ground distance ", names[i], " = ", s[i],
                       " must be finite and > 0"));
    }
  }
  if (absl::Status s = ValidateSpectralOptions(o.spectral); !s.ok()) return s;
  return ValidateHeatTraceOptions(o.heat);
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
      return absl::InvalidArgumentError(absl::StrCat(
          "feature ", i, ": weight ", x.weight, " must be finite and >= 0"));
    }
    if (!std::isfinite(x.integral_geodesic)) {
      return absl::InvalidArgumentError(
          absl::StrCat("feature ", i, ": integral geodesic is not finite"));
    }
    if (x.curvature.size() != bands || x.area.size() != bands ||
        x.distance.size() != bands) {
      return absl::InvalidArgumentError(absl::StrCat(
          "feature ", i, ": curvature, area, distance have lengths ",
          x.curvature.size(), ", ", x.area.size(), ", ", x.distance.size(),
          "; expected ", bands, " each (the length of feature 0's curvature)"));
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
    return absl::InvalidArgumentError(
        absl::StrCat("spectrum has ", signature.spectrum.size(),
                     " values, at most ", kMaxSpectrum, " are supported"));
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

PreparedSignature::~PreparedSignature() { Release(); }

void PreparedSignature::Release() noexcept {
  if (owns_block_) delete[] block_;
  block_ = nullptr;
  owns_block_ = false;
  size_ = bands_ = 0;
  spectral_size_ = heat_size_ = 0;
  serial_ = 0;
}

PreparedSignature::PreparedSignature(const PreparedSignature& other)
    : size_(other.size_),
      bands_(other.bands_),
      spectral_size_(other.spectral_size_),
      heat_size_(other.heat_size_),
      serial_(other.serial_) {
  if (other.block_ != nullptr) {
    block_ = new std::byte[BlockBytes()];
    owns_block_ = true;
    std::memcpy(block_, other.block_, BlockBytes());
  }
}

PreparedSignature& PreparedSignature::operator=(
    const PreparedSignature& other) {
  if (this != &other) *this = PreparedSignature(other);
  return *this;
}

PreparedSignature::PreparedSignature(PreparedSignature&& other) noexcept
    : size_(other.size_),
      bands_(other.bands_),
      spectral_size_(other.spectral_size_),
      heat_size_(other.heat_size_),
      owns_block_(other.owns_block_),
      serial_(other.serial_),
      block_(other.block_) {
  other.block_ = nullptr;
  other.owns_block_ = false;
  other.Release();
}

PreparedSignature& PreparedSignature::operator=(
    PreparedSignature&& other) noexcept {
  if (this != &other) {
    Release();
    size_ = other.size_;
    bands_ = other.bands_;
    spectral_size_ = other.spectral_size_;
    heat_size_ = other.heat_size_;
    owns_block_ = other.owns_block_;
    serial_ = other.serial_;
    block_ = other.block_;
    other.block_ = nullptr;
    other.owns_block_ = false;
    other.Release();
  }
  return *this;
}

PreparedSignature PreparedSignature::CopyInto(std::byte* storage) const {
  assert(block_ != nullptr && storage != nullptr);
  assert(reinterpret_cast<uintptr_t>(storage) % alignof(double) == 0);
  PreparedSignature view;
  view.size_ = size_;
  view.bands_ = bands_;
  view.spectral_size_ = spectral_size_;
  view.heat_size_ = heat_size_;
  view.serial_ = serial_;
  std::memcpy(storage, block_, BlockBytes());
  view.block_ = storage;
  view.owns_block_ = false;
  return view;
}

absl::StatusOr<PreparedSignature> Prepare(
    const Signature& signature, const GroundDistanceOptions& options) {
  if (absl::Status s = ValidateOptions(options); !s.ok()) return s;
  if (absl::Status s = ValidateSignature(signature); !s.ok()) return s;
  const auto& f = signature.features;
  static std::atomic<uint64_t> next_serial{1};
  PreparedSignature p;
  p.serial_ = next_serial.fetch_add(1, std::memory_order_relaxed);
  p.size_ = static_cast<int>(f.size());
  p.bands_ = static_cast<int>(f[0].curvature.size());
  const int n = p.size_;
  const int bands = p.bands_;
  const size_t un = static_cast<size_t>(n);
  const size_t rows = static_cast<size_t>(p.rows());
  std::vector<double> spectral =
      SpectralEmbedding(signature.spectrum, options.spectral);
  std::vector<double> heat =
      HeatTraceEmbedding(signature.spectrum, options.heat);
  p.spectral_size_ = static_cast<uint16_t>(spectral.size());
  p.heat_size_ = static_cast<uint16_t>(heat.size());
  p.block_ = new std::byte[p.BlockBytes()];
  p.owns_block_ = true;
  double* weights = reinterpret_cast<double*>(p.block_);
  float* spectral32 = reinterpret_cast<float*>(p.block_ + sizeof(double) * un);
  float* heat32 = spectral32 + spectral.size();
  float* coords = heat32 + heat.size();

  double sum = 0.0;
  for (const Feature& x : f) sum += x.weight;
  for (size_t i = 0; i < un; ++i) weights[i] = f[i].weight / sum;
  for (size_t i = 0; i < spectral.size(); ++i) {
    spectral32[i] = static_cast<float>(spectral[i]);
    if (!std::isfinite(spectral32[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("spectrum[", i,
                       "] is too large (beyond float32 range once embedded)"));
    }
  }
  // A heat-trace coordinate is log(t Z(t)): -infinity when every exp(-s t)
  // underflows (a spectrum of huge values only).
  for (size_t i = 0; i < heat.size(); ++i) {
    heat32[i] = static_cast<float>(heat[i]);
    if (!std::isfinite(heat32[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("spectrum: heat trace at scale ", i,
                       " is not finite (every eigenvalue too large)"));
    }
  }

  // phi(U) of ground_distance.h, dimension-major, rounded to float32.
  const double ck = options.w2 * options.k_scale;
  const double ca = options.w3 * options.a_scale;
  const double ch = options.w4 * options.h_scale;
  for (size_t i = 0; i < un; ++i) {
    const Feature& x = f[i];
    coords[i] = static_cast<float>(options.w1 * x.integral_geodesic);
    for (size_t b = 0; b < static_cast<size_t>(bands); ++b) {
      coords[(1 + b) * un + i] = static_cast<float>(ck * x.curvature[b]);
      coords[(1 + bands + b) * un + i] = static_cast<float>(ca * x.area[b]);
      coords[(1 + 2 * bands + b) * un + i] =
          static_cast<float>(ch * x.distance[b]);
    }
  }
  // A finite double beyond float32's range (about 3.4e38) would become
  // infinite in storage and poison every distance to it.
  for (size_t r = 0; r < rows; ++r) {
    for (size_t i = 0; i < un; ++i) {
      if (!std::isfinite(coords[r * un + i])) {
        return absl::InvalidArgumentError(absl::StrCat(
            "feature ", i, ": ", r == 0 ? "integral geodesic" : "a band value",
            " is too large (beyond float32 range once weighted)"));
      }
    }
  }
  return p;
}

namespace {

// Squared L2 distance of one band block between feature i of a and feature
// j of b, the shorter vector padded with zeros.
double BlockSquared(const PreparedSignature& a, int i, int a_row0,
                    const PreparedSignature& b, int j, int b_row0) {
  const int common = std::min(a.bands(), b.bands());
  const float* ac = a.coords();
  const float* bc = b.coords();
  const size_t as = static_cast<size_t>(a.size());
  const size_t bs = static_cast<size_t>(b.size());
  double s = 0.0;
  for (int d = 0; d < common; ++d) {
    const double diff = static_cast<double>(ac[(a_row0 + d) * as + i]) -
                        static_cast<double>(bc[(b_row0 + d) * bs + j]);
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
  const double g = std::abs(static_cast<double>(a.coords()[i]) -
                            static_cast<double>(b.coords()[j]));
  const double k = std::sqrt(BlockSquared(a, i, 1, b, j, 1));
  const double ar =
      std::sqrt(BlockSquared(a, i, 1 + a.bands(), b, j, 1 + b.bands()));
  const double h =
      std::sqrt(BlockSquared(a, i, 1 + 2 * a.bands(), b, j, 1 + 2 * b.bands()));
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
// at run time. Lanes run over 8 consecutive features of b (the
// dimension-major layout of PreparedSignature); a's coordinates are
// broadcast. Coordinates are stored in float32 without padding: b's are
// widened to double once per matrix (Widen, features at or past b.size()
// as 0), so the arithmetic is the scalar kernel's. Each lane accumulates
// its bands in the same order, so the matrix is symmetric under swapping a
// and b exactly: (x - y)^2 and (y - x)^2 are the same double and
// fma(d, d, s) depends on d only through d * d.

// WideBuffer returns the calling thread's buffer for Widen and
// WidenAvx512, grown to b's widened size (rows x blocks of 8 doubles).
double* WideBuffer(const PreparedSignature& b) {
  thread_local std::vector<double> buffer;
  const size_t size =
      static_cast<size_t>(b.rows()) * (static_cast<size_t>(b.stride()) / 8) * 8;
  if (buffer.size() < size) buffer.resize(size);
  return buffer.data();
}

// Widen returns b's float32 coordinates widened to double in a per-thread
// buffer, block by block: columns 8k .. 8k + 7 of row r at [(k rows + r) 8]
// (rows = b.rows()), columns at or past b.size() as 0. It reads b's
// coordinates once, row after row in memory order, so that a signature
// not in cache streams in behind the hardware prefetcher. Widening each
// block of 8 features in its own strided pass, with a variable-length
// zero fill per row, cost as much CPU as the distance arithmetic in a
// 10-NN search (perf; docs/search-cost.md). No allocation after warm-up.
const double* Widen(const PreparedSignature& b) {
  double* const buffer = WideBuffer(b);
  const size_t rows = static_cast<size_t>(b.rows());
  const size_t n = static_cast<size_t>(b.size());
  const size_t blocks = static_cast<size_t>(b.stride()) / 8;
  const float* in = b.coords();
  for (size_t r = 0; r < rows; ++r, in += n) {
    for (size_t k = 0; k < blocks; ++k) {
      double* out = buffer + (k * rows + r) * 8;
      const float* x = in + 8 * k;
      if (8 * k + 8 <= n) {  // fixed length: vectorized
        for (int c = 0; c < 8; ++c) out[c] = static_cast<double>(x[c]);
      } else {
        for (int c = 0; c < 8; ++c) out[c] = 0.0;
        for (size_t c = 0; c < n - 8 * k; ++c) {
          out[c] = static_cast<double>(x[c]);
        }
      }
    }
  }
  return buffer;
}

__attribute__((target("avx2,fma"))) double KernelAvx2(
    const PreparedSignature& a, const PreparedSignature& b, double* out,
    int out_stride) {
  const int bands = a.bands();
  const size_t as = static_cast<size_t>(a.size());
  const float* ac = a.coords();
  const __m256d sign = _mm256_set1_pd(-0.0);
  __m256d mx = _mm256_setzero_pd();
  const double* wide = Widen(b);
  const size_t rows = static_cast<size_t>(b.rows());
  for (int j0 = 0; j0 < b.stride(); j0 += 8) {
    const double* blk = wide + static_cast<size_t>(j0) * rows;
    for (int i = 0; i < a.size(); ++i) {
      double* row = out + static_cast<size_t>(i) * out_stride;
      __m256d k0 = _mm256_setzero_pd(), k1 = _mm256_setzero_pd();
      __m256d a0 = _mm256_setzero_pd(), a1 = _mm256_setzero_pd();
      __m256d h0 = _mm256_setzero_pd(), h1 = _mm256_setzero_pd();
      for (int d = 0; d < bands; ++d) {
        const size_t rk = static_cast<size_t>(1 + d);
        const size_t ra = rk + static_cast<size_t>(bands);
        const size_t rh = ra + static_cast<size_t>(bands);
        const __m256d xk = _mm256_set1_pd(ac[rk * as + i]);
        const __m256d xa = _mm256_set1_pd(ac[ra * as + i]);
        const __m256d xh = _mm256_set1_pd(ac[rh * as + i]);
        const double* yk = blk + rk * 8;
        const double* ya = blk + ra * 8;
        const double* yh = blk + rh * 8;
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
      const __m256d xg = _mm256_set1_pd(ac[i]);
      __m256d g0 =
          _mm256_andnot_pd(sign, _mm256_sub_pd(xg, _mm256_loadu_pd(blk)));
      __m256d g1 =
          _mm256_andnot_pd(sign, _mm256_sub_pd(xg, _mm256_loadu_pd(blk + 4)));
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
// Avx512Blocks computes the columns of blocks k0 .. k0 + B - 1 of the
// matrix from b's widened coordinates (Widen; `rows` rows per block): each
// broadcast coordinate of a serves B blocks, and the 3 B accumulators are
// independent chains. Every lane accumulates its bands in the one-block
// order, so the values do not depend on B. Returns max(mx, what it wrote).
template <int B>
__attribute__((target("avx512f"))) inline __m512d Avx512Blocks(
    const PreparedSignature& a, const double* wide, size_t rows, int k0,
    double* out, int out_stride, __m512d mx) {
  const int bands = a.bands();
  const size_t as = static_cast<size_t>(a.size());
  const float* ac = a.coords();
  const double* blk[B];
  for (int b = 0; b < B; ++b) {
    blk[b] = wide + static_cast<size_t>(k0 + b) * rows * 8;
  }
  for (int i = 0; i < a.size(); ++i) {
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

// WidenAvx512 is Widen (same layout, same values: widening float32 to
// double is exact) with one masked load and one conversion per block
// row: Widen's scalar tail for the last, partial block (features 24 ..
// 29 at 30) was about a sixth of the matrix's time at n = m = 30 (perf).
// Masked-off lanes are not read, so nothing past b's block is touched.
__attribute__((target("avx512f"))) const double* WidenAvx512(
    const PreparedSignature& b) {
  double* const buffer = WideBuffer(b);
  const size_t rows = static_cast<size_t>(b.rows());
  const size_t n = static_cast<size_t>(b.size());
  const size_t blocks = static_cast<size_t>(b.stride()) / 8;
  const float* in = b.coords();
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
  return buffer;
}

__attribute__((target("avx512f"))) double KernelAvx512(
    const PreparedSignature& a, const PreparedSignature& b, double* out,
    int out_stride) {
  const double* wide = WidenAvx512(b);
  const size_t rows = static_cast<size_t>(b.rows());
  const int blocks = b.stride() / 8;
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

// Avx512Rows32 computes rows i0 .. i0 + I - 1 of the float32 matrix
// (GroundDistanceMatrix32), all of b's 16-feature blocks: per block, each
// row of b's coordinates is one masked load straight from the stored
// float32 values (no widening; lanes past b.size() read as 0), shared by
// the I rows of a, whose 3 I accumulators are independent chains.
template <int I>
__attribute__((target("avx512f"))) inline void Avx512Rows32(
    const PreparedSignature& a, const PreparedSignature& b, int i0, float* out,
    int out_stride) {
  const int bands = a.bands();
  const size_t as = static_cast<size_t>(a.size());
  const size_t bs = static_cast<size_t>(b.size());
  const float* ac = a.coords() + i0;
  for (int j0 = 0; j0 < b.size(); j0 += 16) {
    const int lanes = std::min(16, b.size() - j0);
    const __mmask16 mask = static_cast<__mmask16>((1u << lanes) - 1u);
    const float* bc = b.coords() + j0;
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

__attribute__((target("avx512f"))) void KernelAvx512Float(
    const PreparedSignature& a, const PreparedSignature& b, float* out,
    int out_stride) {
  int i = 0;
  for (; i + 4 <= a.size(); i += 4) Avx512Rows32<4>(a, b, i, out, out_stride);
  for (; i < a.size(); ++i) Avx512Rows32<1>(a, b, i, out, out_stride);
}
#pragma GCC diagnostic pop
#endif

// KernelByNumber returns kernel `kernel` (numbers as in
// internal::KernelSupported); the portable one for a number this build has
// no kernel for.
KernelFn KernelByNumber(int kernel) {
  switch (kernel) {
#ifdef TPR_HAVE_X86_KERNELS
    case 1:
      return KernelAvx2;
    case 2:
      return KernelAvx512;
#endif
    default:
      return KernelScalar;
  }
}

}  // namespace

double GroundDistanceMatrix(const PreparedSignature& a,
                            const PreparedSignature& b, double* out,
                            int out_stride) {
  assert(out_stride >= b.stride());
  static const KernelFn kernel = KernelByNumber(internal::ChosenKernel());
  if (a.bands() != b.bands()) return KernelScalar(a, b, out, out_stride);
  return kernel(a, b, out, out_stride);
}

namespace internal {

bool KernelSupported(int kernel) {
  switch (kernel) {
    case 0:
      return true;
#ifdef TPR_HAVE_X86_KERNELS
    case 1:
      __builtin_cpu_init();
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    case 2:
      __builtin_cpu_init();
      return __builtin_cpu_supports("avx512f");
#endif
    default:
      return false;
  }
}

int ChosenKernel() {
  static const int chosen = [] {
    for (int kernel = 2; kernel > 0; --kernel) {
      if (KernelSupported(kernel)) return kernel;
    }
    return 0;
  }();
  return chosen;
}

bool GroundDistanceMatrix32(const PreparedSignature& a,
                            const PreparedSignature& b, float* out,
                            int out_stride) {
  assert(out_stride >= Stride32(b) && out_stride % 16 == 0);
#ifdef TPR_HAVE_X86_KERNELS
  static const bool supported = KernelSupported(2);
  if (!supported || a.bands() != b.bands()) return false;
  KernelAvx512Float(a, b, out, out_stride);
  return true;
#else
  (void)a;
  (void)b;
  (void)out;
  (void)out_stride;
  return false;
#endif
}

bool GroundDistanceMatrixWithKernel(int kernel, const PreparedSignature& a,
                                    const PreparedSignature& b, double* out,
                                    int out_stride) {
  if (!KernelSupported(kernel)) return false;
  if (a.bands() != b.bands() && kernel != 0) return false;
  KernelByNumber(kernel)(a, b, out, out_stride);
  return true;
}

}  // namespace internal
}  // namespace tpr::index
