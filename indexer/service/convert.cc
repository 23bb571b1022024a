#include "indexer/service/convert.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "indexer/lib/ground_distance.h"

namespace tpr::indexer {
namespace {

// Rounding slack for fractions computed as sums of floating-point areas.
constexpr double kAreaSlack = 1e-9;

// CheckBand returns INVALID_ARGUMENT naming feature `i`, `field` and the
// band at fault when an entry of `values` is not finite or outside [lo, hi].
absl::Status CheckBand(int i, const char* field,
                       const google::protobuf::RepeatedField<double>& values,
                       double lo, double hi) {
  for (int b = 0; b < values.size(); ++b) {
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

}  // namespace

absl::StatusOr<tpr::index::Signature> ToIndexSignature(
    const tpr::v1::Signature& s) {
  if (s.features_size() == 0) {
    return absl::InvalidArgumentError("signature has no feature");
  }
  if (s.signature_version() < kSignatureVersion) {
    return absl::FailedPreconditionError(absl::StrCat(
        "signature version ", std::max(1, s.signature_version()),
        " is older than version ", kSignatureVersion,
        " (which adds the Laplace-Beltrami spectrum) that this indexer "
        "compares; re-extract the model with a current tpr-extractor: `tpr add "
        "--update`"));
  }
  if (s.signature_version() > kSignatureVersion) {
    return absl::FailedPreconditionError(absl::StrCat(
        "signature version ", s.signature_version(), " is newer than version ",
        kSignatureVersion, " that this indexer compares; upgrade tpr-indexer"));
  }
  if (s.features_size() > tpr::index::kMaxFeatures) {
    return absl::ResourceExhaustedError(
        absl::StrCat("signature has ", s.features_size(), " features; at most ",
                     tpr::index::kMaxFeatures, " are accepted"));
  }
  const int bands = s.options().bands();
  if (bands < 1 || bands > kMaxBands) {
    return absl::InvalidArgumentError(
        absl::StrCat("signature options.bands is ", bands, "; must be in 1..",
                     kMaxBands, " (the extractor fills it)"));
  }
  constexpr double kInf = HUGE_VAL;
  tpr::index::Signature out;
  out.features.reserve(static_cast<size_t>(s.features_size()));
  for (int i = 0; i < s.features_size(); ++i) {
    const tpr::v1::Feature& f = s.features(i);
    if (f.kind() != tpr::v1::FEATURE_KIND_POINT &&
        f.kind() != tpr::v1::FEATURE_KIND_RING) {
      return absl::InvalidArgumentError(absl::StrCat(
          "signature feature ", i, " has no kind (point or ring)"));
    }
    if (f.curvature_size() != bands || f.area_size() != bands ||
        f.distance_size() != bands) {
      return absl::InvalidArgumentError(absl::StrCat(
          "signature feature ", i, ": curvature, area, distance have ",
          f.curvature_size(), ", ", f.area_size(), ", ", f.distance_size(),
          " entries; each must have options.bands = ", bands));
    }
    if (!(f.weight() >= 0.0 && f.weight() < kInf)) {
      return absl::InvalidArgumentError(
          absl::StrCat("signature feature ", i, ": weight is ", f.weight(),
                       "; must be finite and >= 0"));
    }
    if (!(f.integral_geodesic() >= 0.0 && f.integral_geodesic() <= 1.0)) {
      return absl::InvalidArgumentError(
          absl::StrCat("signature feature ", i, ": integral_geodesic is ",
                       f.integral_geodesic(), "; must be in [0, 1]"));
    }
    if (absl::Status st = CheckBand(i, "curvature", f.curvature(),
                                    -kMaxBandMagnitude, kMaxBandMagnitude);
        !st.ok() ||
        !(st = CheckBand(i, "area", f.area(), 0.0, 1.0 + kAreaSlack)).ok() ||
        !(st = CheckBand(i, "distance", f.distance(), 0.0, kMaxBandMagnitude))
             .ok()) {
      return st;
    }
    tpr::index::Feature g;
    g.weight = f.weight();
    g.integral_geodesic = f.integral_geodesic();
    g.curvature.assign(f.curvature().begin(), f.curvature().end());
    g.area.assign(f.area().begin(), f.area().end());
    g.distance.assign(f.distance().begin(), f.distance().end());
    out.features.push_back(std::move(g));
  }
  // options.spectrum_eigenvalues 0 means "the default", so only the hard
  // bound applies then.
  const int requested = s.options().spectrum_eigenvalues();
  const int max_spectrum = requested > 0
                               ? std::min(requested, tpr::index::kMaxSpectrum)
                               : tpr::index::kMaxSpectrum;
  if (s.spectrum_size() > max_spectrum) {
    return absl::InvalidArgumentError(absl::StrCat(
        "signature spectrum has ", s.spectrum_size(), " values; at most ",
        max_spectrum, " allowed (options.spectrum_eigenvalues is ", requested,
        ")"));
  }
  for (int i = 0; i < s.spectrum_size(); ++i) {
    const double x = s.spectrum(i);
    if (!std::isfinite(x) || x <= 0.0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "signature spectrum[", i, "] is ", x, "; must be finite and > 0"));
    }
    if (i > 0 && x < s.spectrum(i - 1)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "signature spectrum[", i, "] is ", x, ", below spectrum[", i - 1,
          "] = ", s.spectrum(i - 1), "; must be ascending"));
    }
  }
  out.spectrum.assign(s.spectrum().begin(), s.spectrum().end());
  // What is left for the library's own check: the weights' sum (Eq. 6).
  if (absl::Status valid = tpr::index::ValidateSignature(out); !valid.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("malformed signature: ", valid.message()));
  }
  return out;
}

tpr::v1::Signature ToWireSignature(const tpr::index::Signature& s, int points) {
  tpr::v1::Signature out;
  for (size_t i = 0; i < s.features.size(); ++i) {
    const tpr::index::Feature& f = s.features[i];
    tpr::v1::Feature* w = out.add_features();
    w->set_kind(static_cast<int>(i) < points ? tpr::v1::FEATURE_KIND_POINT
                                             : tpr::v1::FEATURE_KIND_RING);
    w->set_weight(f.weight);
    w->set_integral_geodesic(f.integral_geodesic);
    w->mutable_curvature()->Add(f.curvature.begin(), f.curvature.end());
    w->mutable_area()->Add(f.area.begin(), f.area.end());
    w->mutable_distance()->Add(f.distance.begin(), f.distance.end());
  }
  if (!s.features.empty()) {
    out.mutable_options()->set_bands(
        static_cast<int>(s.features[0].curvature.size()));
  }
  out.mutable_spectrum()->Add(s.spectrum.begin(), s.spectrum.end());
  out.mutable_options()->set_spectrum_eigenvalues(
      std::max(1, static_cast<int>(s.spectrum.size())));
  out.set_signature_version(kSignatureVersion);
  out.set_extractor_version("test");
  return out;
}

absl::StatusOr<tpr::index::TermWeights> ToTermWeights(
    const tpr::v1::SearchRequest& request) {
  if (request.has_ranking()) {
    const tpr::v1::Ranking& r = request.ranking();
    const tpr::index::TermWeights w{r.emd_weight(), r.spectral_weight(),
                                    r.heat_weight()};
    if (absl::Status s = tpr::index::ValidateTermWeights(w); !s.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("ranking: ", s.message()));
    }
    return w;
  }
  switch (request.intent()) {
    case tpr::v1::INTENT_UNSPECIFIED:
    case tpr::v1::INTENT_BALANCED:
      return tpr::index::IntentWeights(tpr::index::Intent::kBalanced);
    case tpr::v1::INTENT_IDENTITY:
      return tpr::index::IntentWeights(tpr::index::Intent::kIdentity);
    case tpr::v1::INTENT_KIND:
      return tpr::index::IntentWeights(tpr::index::Intent::kKind);
    default:
      return absl::InvalidArgumentError(absl::StrCat(
          "intent ", static_cast<int>(request.intent()),
          " is not one of INTENT_BALANCED (1), INTENT_IDENTITY (2), "
          "INTENT_KIND (3)"));
  }
}

tpr::v1::Intent ToWireIntent(tpr::index::Intent intent) {
  switch (intent) {
    case tpr::index::Intent::kBalanced:
      return tpr::v1::INTENT_BALANCED;
    case tpr::index::Intent::kIdentity:
      return tpr::v1::INTENT_IDENTITY;
    case tpr::index::Intent::kKind:
      return tpr::v1::INTENT_KIND;
  }
  return tpr::v1::INTENT_BALANCED;
}

}  // namespace tpr::indexer
