#include "indexer/lib/signature_check.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/signature_limits.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/spectral.h"

namespace tpr::index {
namespace {

// Rounding slack for fractions computed as sums of floating-point areas.
constexpr double kAreaSlack = 1e-9;

// CheckBand returns INVALID_ARGUMENT naming feature `i`, `field` and the
// band at fault when an entry of `values` is not finite or outside [lo, hi].
absl::Status CheckBand(size_t i, const char* field,
                       const std::vector<double>& values, double lo,
                       double hi) {
  for (size_t b = 0; b < values.size(); ++b) {
    const double x = values[b];
    if (!std::isfinite(x) || x < lo || x > hi) {
      const std::string range =
          std::isfinite(hi)   ? absl::StrCat(" and in [", lo, ", ", hi, "]")
          : std::isfinite(lo) ? absl::StrCat(" and >= ", lo)
                              : "";
      return absl::InvalidArgumentError(
          absl::StrCat("signature feature ", i, ": ", field, "[", b, "] is ", x,
                       "; must be finite", range));
    }
  }
  return absl::OkStatus();
}

// CheckFeature checks feature `i` of a signature of `bands` bands.
absl::Status CheckFeature(size_t i, const Feature& f, size_t bands) {
  if (f.curvature.size() != bands || f.area.size() != bands ||
      f.distance.size() != bands) {
    return absl::InvalidArgumentError(absl::StrCat(
        "signature feature ", i, ": curvature, area, distance have ",
        f.curvature.size(), ", ", f.area.size(), ", ", f.distance.size(),
        " entries; each must have options.bands = ", bands));
  }
  if (!(f.weight >= 0.0 && f.weight < HUGE_VAL)) {
    return absl::InvalidArgumentError(
        absl::StrCat("signature feature ", i, ": weight is ", f.weight,
                     "; must be finite and >= 0"));
  }
  if (!(f.integral_geodesic >= 0.0 && f.integral_geodesic <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("signature feature ", i, ": integral_geodesic is ",
                     f.integral_geodesic, "; must be in [0, 1]"));
  }
  if (absl::Status st = CheckBand(i, "curvature", f.curvature,
                                  -kMaxBandMagnitude, kMaxBandMagnitude);
      !st.ok()) {
    return st;
  }
  if (absl::Status st = CheckBand(i, "area", f.area, 0.0, 1.0 + kAreaSlack);
      !st.ok()) {
    return st;
  }
  return CheckBand(i, "distance", f.distance, 0.0, kMaxBandMagnitude);
}

// CheckSpectrum checks the spectrum's length and values.
absl::Status CheckSpectrum(const std::vector<double>& spectrum,
                           int max_spectrum, int requested) {
  if (spectrum.size() > static_cast<size_t>(max_spectrum)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "signature spectrum has ", spectrum.size(), " values; at most ",
        max_spectrum, " allowed (options.spectrum_eigenvalues is ", requested,
        ")"));
  }
  for (size_t i = 0; i < spectrum.size(); ++i) {
    const double x = spectrum[i];
    if (!std::isfinite(x) || x <= 0.0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "signature spectrum[", i, "] is ", x, "; must be finite and > 0"));
    }
    if (i > 0 && x < spectrum[i - 1]) {
      return absl::InvalidArgumentError(absl::StrCat(
          "signature spectrum[", i, "] is ", x, ", below spectrum[", i - 1,
          "] = ", spectrum[i - 1], "; must be ascending"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status CheckSignatureContract(const Signature& s, int max_spectrum) {
  if (!s.features.empty()) {
    const size_t bands = s.features[0].curvature.size();
    if (!common::BandsInRange(static_cast<int>(bands))) {
      return absl::InvalidArgumentError(
          absl::StrCat("signature options.bands is ", bands, "; must be in ",
                       common::kMinBands, "..", common::kMaxBands,
                       " (the extractor fills it)"));
    }
    for (size_t i = 0; i < s.features.size(); ++i) {
      if (absl::Status st = CheckFeature(i, s.features[i], bands); !st.ok()) {
        return st;
      }
    }
  }
  // options.spectrum_eigenvalues 0 means "the default", so only the hard
  // bound applies then.
  const int limit =
      max_spectrum > 0 ? std::min(max_spectrum, kMaxSpectrum) : kMaxSpectrum;
  if (absl::Status st = CheckSpectrum(s.spectrum, limit, max_spectrum);
      !st.ok()) {
    return st;
  }
  // What is left for the library's own check: the weights' sum (Eq. 6).
  if (absl::Status valid = ValidateSignature(s); !valid.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("malformed signature: ", valid.message()));
  }
  return absl::OkStatus();
}

}  // namespace tpr::index
