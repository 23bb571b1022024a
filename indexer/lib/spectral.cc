#include "indexer/lib/spectral.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace tpr::index {

const char* SpectralTransformName(SpectralTransform t) {
  switch (t) {
    case SpectralTransform::kRaw:
      return "raw";
    case SpectralTransform::kByIndex:
      return "by_index";
    case SpectralTransform::kLog:
      return "log";
  }
  return "?";
}

absl::StatusOr<SpectralTransform> ParseSpectralTransform(
    absl::string_view name) {
  for (SpectralTransform t :
       {SpectralTransform::kRaw, SpectralTransform::kByIndex,
        SpectralTransform::kLog}) {
    if (name == SpectralTransformName(t)) return t;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "spectral transform '", name, "' is not one of raw, by_index, log"));
}

absl::Status ValidateSpectralOptions(const SpectralOptions& o) {
  if (o.eigenvalues < 1 || o.eigenvalues > kMaxSpectrum) {
    return absl::InvalidArgumentError(
        absl::StrCat("spectral eigenvalues ", o.eigenvalues, " must be in 1..",
                     kMaxSpectrum));
  }
  switch (o.transform) {
    case SpectralTransform::kRaw:
    case SpectralTransform::kByIndex:
    case SpectralTransform::kLog:
      return absl::OkStatus();
  }
  return absl::InvalidArgumentError(
      "spectral transform is not raw, by_index or log");
}

std::vector<double> SpectralEmbedding(const std::vector<double>& spectrum,
                                      const SpectralOptions& options) {
  const size_t n = static_cast<size_t>(options.eigenvalues);
  const double scale = 1.0 / std::sqrt(static_cast<double>(n));
  std::vector<double> e(n);
  for (size_t k = 0; k < n; ++k) {
    const double i = static_cast<double>(k + 1);
    const double x = k < spectrum.size() ? spectrum[k] : i;  // Weyl asymptote
    double phi = x;
    switch (options.transform) {
      case SpectralTransform::kRaw:
        break;
      case SpectralTransform::kByIndex:
        phi = x / i;
        break;
      case SpectralTransform::kLog:
        phi = std::log(x);
        break;
    }
    e[k] = scale * phi;
  }
  return e;
}

absl::Status ValidateHeatTraceOptions(const HeatTraceOptions& o) {
  if (o.scales < 0 || o.scales > 256) {
    return absl::InvalidArgumentError(
        absl::StrCat("heat-trace scales ", o.scales, " must be in 0..256"));
  }
  if (!(std::isfinite(o.t_min) && std::isfinite(o.t_max) && o.t_min > 0.0 &&
        o.t_min < o.t_max)) {
    return absl::InvalidArgumentError(
        absl::StrCat("heat-trace times [", o.t_min, ", ", o.t_max,
                     "] must satisfy 0 < t_min < t_max"));
  }
  if (o.eigenvalues < 1 || o.eigenvalues > kMaxSpectrum) {
    return absl::InvalidArgumentError(
        absl::StrCat("heat-trace eigenvalues ", o.eigenvalues,
                     " must be in 1..", kMaxSpectrum));
  }
  return absl::OkStatus();
}

std::vector<double> HeatTraceEmbedding(const std::vector<double>& spectrum,
                                       const HeatTraceOptions& options) {
  const size_t m = static_cast<size_t>(options.scales);
  if (m == 0) return {};
  const size_t n = static_cast<size_t>(options.eigenvalues);
  const double scale = 1.0 / std::sqrt(static_cast<double>(m));
  const double log_ratio = std::log(options.t_max / options.t_min);
  std::vector<double> f(m);
  for (size_t j = 0; j < m; ++j) {
    const double step = m == 1 ? 0.0 : static_cast<double>(j) / (m - 1);
    const double t = options.t_min * std::exp(step * log_ratio);
    double z = 0.0;
    for (size_t k = 0; k < n; ++k) {
      const double x =
          k < spectrum.size() ? spectrum[k] : static_cast<double>(k + 1);
      z += std::exp(-x * t);
    }
    f[j] = scale * std::log(t * z);
  }
  return f;
}

namespace {

template <typename T>
double EuclideanDistance(const T* a, const T* b, size_t n) {
  double s = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const double d = static_cast<double>(a[i]) - static_cast<double>(b[i]);
    s += d * d;
  }
  return std::sqrt(s);
}

}  // namespace

double SpectralDistance(const double* a, const double* b, size_t n) {
  return EuclideanDistance(a, b, n);
}

double SpectralDistance(const float* a, const float* b, size_t n) {
  return EuclideanDistance(a, b, n);
}

}  // namespace tpr::index
