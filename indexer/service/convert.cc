#include "indexer/service/convert.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/status_macros.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/signature_check.h"

namespace tpr::indexer {
absl::StatusOr<tpr::index::Signature> ToIndexSignature(
    const tpr::v1::Signature& s) {
  if (s.features_size() == 0) {
    return absl::InvalidArgumentError("signature has no feature");
  }
  if (s.signature_version() < kSignatureVersion) {
    return absl::FailedPreconditionError(absl::StrCat(
        "signature version ", std::max(1, s.signature_version()),
        " is older than version ", kSignatureVersion,
        " (whose spectrum the spectral and heat-trace terms compare) that "
        "this indexer compares; re-extract the model with a current "
        "tpr-extractor: `tpr add --update`"));
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
  if (!common::BandsInRange(bands)) {
    return absl::InvalidArgumentError(
        absl::StrCat("signature options.bands is ", bands, "; must be in 1..",
                     kMaxBands, " (the extractor fills it)"));
  }
  tpr::index::Signature out;
  out.features.reserve(static_cast<size_t>(s.features_size()));
  for (int i = 0; i < s.features_size(); ++i) {
    const tpr::v1::Feature& f = s.features(i);
    if (f.kind() != tpr::v1::FEATURE_KIND_POINT &&
        f.kind() != tpr::v1::FEATURE_KIND_RING) {
      return absl::InvalidArgumentError(absl::StrCat(
          "signature feature ", i, " has no kind (point or ring)"));
    }
    // Before copying, so that an oversized band vector costs nothing.
    if (f.curvature_size() != bands || f.area_size() != bands ||
        f.distance_size() != bands) {
      return absl::InvalidArgumentError(absl::StrCat(
          "signature feature ", i, ": curvature, area, distance have ",
          f.curvature_size(), ", ", f.area_size(), ", ", f.distance_size(),
          " entries; each must have options.bands = ", bands));
    }
    tpr::index::Feature g;
    g.weight = f.weight();
    g.integral_geodesic = f.integral_geodesic();
    g.curvature.assign(f.curvature().begin(), f.curvature().end());
    g.area.assign(f.area().begin(), f.area().end());
    g.distance.assign(f.distance().begin(), f.distance().end());
    out.features.push_back(std::move(g));
  }
  out.spectrum.assign(s.spectrum().begin(), s.spectrum().end());
  // Every value range and the weights' sum: the library-form check the
  // in-process bridge (eval/lib/tpr_descriptor.cc) uses too.
  TPR_RETURN_IF_ERROR(tpr::index::CheckSignatureContract(
      out, s.options().spectrum_eigenvalues()));
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
