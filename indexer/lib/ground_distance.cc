// Ground distance of Eq. 7 and signature preparation. See ground_distance.h
// for the definition of L2norm and why the result is a metric.
#include "indexer/lib/ground_distance.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"

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
  return absl::OkStatus();
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
  const size_t bands = f[0].k.size();
  double sum = 0.0;
  for (size_t i = 0; i < f.size(); ++i) {
    const Feature& x = f[i];
    if (!std::isfinite(x.weight) || x.weight < 0.0) {
      return absl::InvalidArgumentError(
          absl::StrCat("feature ", i, ": weight ", x.weight,
                       " must be finite and >= 0"));
    }
    if (!std::isfinite(x.g)) {
      return absl::InvalidArgumentError(
          absl::StrCat("feature ", i, ": integral geodesic is not finite"));
    }
    if (x.k.size() != bands || x.a.size() != bands || x.h.size() != bands) {
      return absl::InvalidArgumentError(absl::StrCat(
          "feature ", i, ": band vectors K, A, H have lengths ", x.k.size(),
          ", ", x.a.size(), ", ", x.h.size(), "; expected ", bands,
          " each (the length of feature 0's K)"));
    }
    if (!AllFinite(x.k) || !AllFinite(x.a) || !AllFinite(x.h)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "feature ", i, ": a band vector holds a non-finite value"));
    }
    sum += x.weight;
  }
  if (std::abs(sum - 1.0) > 1e-6) {
    return absl::InvalidArgumentError(absl::StrCat(
        "signature weights sum to ", sum, ", must sum to 1 (Eq. 6)"));
  }
  return absl::OkStatus();
}

absl::StatusOr<PreparedSignature> Prepare(const Signature& signature,
                                          const GroundDistanceOptions& options) {
  if (absl::Status s = ValidateOptions(options); !s.ok()) return s;
  if (absl::Status s = ValidateSignature(signature); !s.ok()) return s;
  const auto& f = signature.features;
  PreparedSignature p;
  p.size_ = static_cast<int>(f.size());
  p.bands_ = static_cast<int>(f[0].k.size());
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
    p.coords_[i] = options.w1 * x.g;
    for (int b = 0; b < bands; ++b) {
      p.coords_[(1 + b) * stride + i] = ck * x.k[b];
      p.coords_[(1 + bands + b) * stride + i] = ca * x.a[b];
      p.coords_[(1 + 2 * bands + b) * stride + i] = ch * x.h[b];
    }
  }
  p.centroid_.assign(rows, 0.0);
  for (size_t r = 0; r < rows; ++r) {
    double c = 0.0;
    for (int i = 0; i < n; ++i) c += p.weights_[i] * p.coords_[r * stride + i];
    p.centroid_[r] = c;
  }
  return p;
}

namespace {

// Squared L2 distance of one band block between feature i of a and feature
// j of b, the shorter vector padded with zeros. The summation order (band 0
// upwards) is the same as in the vectorized kernel below, so both give
// bit-identical results (no FMA contraction under -std=c++17).
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

// One row of the matrix: feature i of a against every feature of b. The
// inner loops run over b's features (contiguous, padded), so the compiler
// vectorizes them; each lane accumulates its bands in the same order as
// BlockSquared.
template <int kMaxChunk>
inline void KernelRow(const PreparedSignature& a, int i,
                      const PreparedSignature& b, double* out) {
  const int bands_a = a.bands();
  const int bands_b = b.bands();
  const int common = std::min(bands_a, bands_b);
  const size_t as = static_cast<size_t>(a.stride());
  const size_t bs = static_cast<size_t>(b.stride());
  const double* ac = a.coords();
  const double* bc = b.coords();
  const int m_pad = b.stride();
  for (int j0 = 0; j0 < m_pad; j0 += kMaxChunk) {
    double acc_k[kMaxChunk];
    double acc_a[kMaxChunk];
    double acc_h[kMaxChunk];
    for (int l = 0; l < kMaxChunk; ++l) acc_k[l] = acc_a[l] = acc_h[l] = 0.0;
    for (int d = 0; d < common; ++d) {
      const double xk = ac[(1 + d) * as + i];
      const double xa = ac[(1 + bands_a + d) * as + i];
      const double xh = ac[(1 + 2 * bands_a + d) * as + i];
      const double* yk = bc + (1 + d) * bs + j0;
      const double* ya = bc + (1 + bands_b + d) * bs + j0;
      const double* yh = bc + (1 + 2 * bands_b + d) * bs + j0;
      for (int l = 0; l < kMaxChunk; ++l) {
        const double dk = xk - yk[l];
        const double da = xa - ya[l];
        const double dh = xh - yh[l];
        acc_k[l] += dk * dk;
        acc_a[l] += da * da;
        acc_h[l] += dh * dh;
      }
    }
    for (int d = common; d < bands_a; ++d) {
      const double xk = ac[(1 + d) * as + i];
      const double xa = ac[(1 + bands_a + d) * as + i];
      const double xh = ac[(1 + 2 * bands_a + d) * as + i];
      for (int l = 0; l < kMaxChunk; ++l) {
        acc_k[l] += xk * xk;
        acc_a[l] += xa * xa;
        acc_h[l] += xh * xh;
      }
    }
    for (int d = common; d < bands_b; ++d) {
      const double* yk = bc + (1 + d) * bs + j0;
      const double* ya = bc + (1 + bands_b + d) * bs + j0;
      const double* yh = bc + (1 + 2 * bands_b + d) * bs + j0;
      for (int l = 0; l < kMaxChunk; ++l) {
        acc_k[l] += yk[l] * yk[l];
        acc_a[l] += ya[l] * ya[l];
        acc_h[l] += yh[l] * yh[l];
      }
    }
    const double xg = ac[i];
    const double* yg = bc + j0;
    for (int l = 0; l < kMaxChunk; ++l) {
      const double g = std::abs(xg - yg[l]);
      out[j0 + l] =
          ((g + std::sqrt(acc_k[l])) + std::sqrt(acc_a[l])) + std::sqrt(acc_h[l]);
    }
  }
}

// The kernel is compiled for AVX2 and for the baseline; the loader picks
// the best the CPU runs (GCC function multiversioning). The build's default
// target is plain x86-64 (SSE2), which would halve the throughput here.
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
#define TPR_MULTIVERSION __attribute__((target_clones("avx2", "default")))
#else
#define TPR_MULTIVERSION
#endif

TPR_MULTIVERSION
void KernelMatrix(const PreparedSignature& a, const PreparedSignature& b,
                  double* out, int out_stride) {
  for (int i = 0; i < a.size(); ++i) {
    KernelRow<8>(a, i, b, out + static_cast<size_t>(i) * out_stride);
  }
}

}  // namespace

void GroundDistanceMatrix(const PreparedSignature& a,
                          const PreparedSignature& b, double* out,
                          int out_stride) {
  assert(out_stride >= b.stride());
  KernelMatrix(a, b, out, out_stride);
}

}  // namespace tpr::index
