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
#include "indexer/lib/internal/ground_distance_kernels.h"

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
// EMD uses to scale its optimality tolerance at no extra pass. The wide
// ones are hand-written (internal/ground_distance_kernels.h): the build
// targets baseline x86-64 (SSE2), GCC does not vectorize sqrt without
// -fno-math-errno, and the matrix is about a third of an EMD.

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

// WideBuffer returns the calling thread's scratch for a wide kernel's
// widened coordinates of b (MatrixFn), grown to b.rows() x b.stride()
// doubles. No allocation after warm-up.
double* WideBuffer(const PreparedSignature& b) {
  thread_local std::vector<double> buffer;
  const size_t size =
      static_cast<size_t>(b.rows()) * static_cast<size_t>(b.stride());
  if (buffer.size() < size) buffer.resize(size);
  return buffer.data();
}

internal::KernelCoords CoordsOf(const PreparedSignature& p) {
  return {p.coords(), p.size(), p.bands()};
}

// MatrixKernelsFor returns the wide matrix kernels of `level`, nullptr for
// the scalar level or one this CPU cannot run.
const internal::MatrixKernels* MatrixKernelsFor(internal::SimdLevel level) {
  if (!internal::SimdLevelSupported(level)) return nullptr;
  switch (level) {
#ifdef TPR_HAVE_X86_KERNELS
    case internal::SimdLevel::kAvx2:
      return internal::MatrixKernelsAvx2Table();
    case internal::SimdLevel::kAvx512:
      return internal::MatrixKernelsAvx512Table();
#endif
    default:
      return nullptr;
  }
}

// The chosen level's wide kernels (nullptr: the scalar level), once.
const internal::MatrixKernels* ChosenMatrixKernels() {
  static const internal::MatrixKernels* const kernels =
      MatrixKernelsFor(internal::ChosenSimdLevel());
  return kernels;
}

double RunMatrix(const internal::MatrixKernels* kernels,
                 const PreparedSignature& a, const PreparedSignature& b,
                 double* out, int out_stride) {
  if (kernels == nullptr || a.bands() != b.bands()) {
    return KernelScalar(a, b, out, out_stride);
  }
  return kernels->matrix(CoordsOf(a), CoordsOf(b), WideBuffer(b), out,
                         out_stride);
}

bool RunMatrix32(const internal::MatrixKernels* kernels,
                 const PreparedSignature& a, const PreparedSignature& b,
                 float* out, int out_stride) {
  assert(out_stride >= internal::Stride32(b) && out_stride % 16 == 0);
  if (kernels == nullptr || a.bands() != b.bands()) return false;
  kernels->matrix32(CoordsOf(a), CoordsOf(b), internal::Stride32(b), out,
                    out_stride);
  return true;
}

}  // namespace

double GroundDistanceMatrix(const PreparedSignature& a,
                            const PreparedSignature& b, double* out,
                            int out_stride) {
  assert(out_stride >= b.stride());
  return RunMatrix(ChosenMatrixKernels(), a, b, out, out_stride);
}

namespace internal {

bool GroundDistanceMatrixAt(SimdLevel level, const PreparedSignature& a,
                            const PreparedSignature& b, double* out,
                            int out_stride) {
  if (!SimdLevelSupported(level)) return false;
  if (level != SimdLevel::kScalar && a.bands() != b.bands()) return false;
  RunMatrix(MatrixKernelsFor(level), a, b, out, out_stride);
  return true;
}

int Stride32(const PreparedSignature& b) { return (b.size() + 15) / 16 * 16; }

bool GroundDistanceMatrix32(const PreparedSignature& a,
                            const PreparedSignature& b, float* out,
                            int out_stride) {
  return RunMatrix32(ChosenMatrixKernels(), a, b, out, out_stride);
}

bool GroundDistanceMatrix32At(SimdLevel level, const PreparedSignature& a,
                              const PreparedSignature& b, float* out,
                              int out_stride) {
  return RunMatrix32(MatrixKernelsFor(level), a, b, out, out_stride);
}

}  // namespace internal
}  // namespace tpr::index
