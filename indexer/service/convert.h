// Conversions between the wire signature (tpr.v1.Signature) and the indexer
// library's (tpr::index::Signature). This is the ONE place where the indexer
// reads a wire signature, and therefore its single validator: every stored,
// upserted or query signature passes through ToIndexSignature. A new feature
// field is added here (both directions), in the proto, in
// indexer/lib/signature.h and in the extractor's converter
// (extractor/service/convert.h); nothing else copies fields.
//
//   absl::StatusOr<index::Signature> s = ToIndexSignature(request.signature());
//   if (!s.ok()) return s.status();  // INVALID_ARGUMENT, names the field
#ifndef TPR_INDEXER_SERVICE_CONVERT_H_
#define TPR_INDEXER_SERVICE_CONVERT_H_

#include "absl/status/statusor.h"
#include "common/signature_limits.h"
#include "indexer/lib/intent.h"
#include "indexer/lib/signature.h"
#include "indexer/lib/signature_check.h"
#include "tpr/v1/indexer.pb.h"
#include "tpr/v1/signature.pb.h"

namespace tpr::indexer {

// kMaxBands (the largest band count a signature may carry) and
// kSignatureVersion (the Signature.signature_version this indexer compares):
// the contract's, defined once in common/signature_limits.h.
using common::kMaxBands;
using common::kSignatureVersion;

// kMaxBandMagnitude bounds |curvature| and distance band values
// (indexer/lib/signature_check.h defines it).
using tpr::index::kMaxBandMagnitude;

// ToIndexSignature validates the wire signature `s` against every range the
// contract (proto/tpr/v1/signature.proto) documents and returns it in the
// library's form: the version, feature count, band count and kinds here,
// the values through tpr::index::CheckSignatureContract. Errors:
//  - FAILED_PRECONDITION: signature_version is not kSignatureVersion (an
//    older one, 0 or 1, says to re-extract with `tpr add --update`);
//  - RESOURCE_EXHAUSTED: more than tpr::index::kMaxFeatures features;
//  - INVALID_ARGUMENT, naming the feature index and field at fault: no
//    feature; options.bands outside 1..256; a feature whose kind is neither
//    point nor ring; curvature, area or distance not of length
//    options.bands; integral_geodesic outside [0, 1]; a weight, area or
//    distance that is negative; an area above 1; a curvature or distance
//    above kMaxBandMagnitude in magnitude; any value not finite;
//    weights not summing to 1 within 1e-6 (Eq. 6); a spectrum longer than
//    tpr::index::kMaxSpectrum or than options.spectrum_eigenvalues when
//    that is set, not
//    ascending, or holding a value that is not finite and > 0.
// O(features x bands); thread-safe.
absl::StatusOr<tpr::index::Signature> ToIndexSignature(
    const tpr::v1::Signature& s);

// ToWireSignature is the inverse of ToIndexSignature for code that builds
// library signatures directly (tests, benchmarks, fuzz seeds): features
// [0, points) become FEATURE_KIND_POINT, the rest FEATURE_KIND_RING (the
// library form does not keep the kind; matching ignores it), options.bands
// is the band vectors' length, options.spectrum_eigenvalues the spectrum's
// length (at least 1), signature_version kSignatureVersion and
// extractor_version "test".
// ToIndexSignature(ToWireSignature(s, p)) == s for every valid s. O(size);
// thread-safe.
tpr::v1::Signature ToWireSignature(const tpr::index::Signature& s, int points);

// ToTermWeights returns the weighting a search ranks by: request.ranking's
// three weights when it is set, else IntentWeights of request.intent
// (INTENT_UNSPECIFIED reads as INTENT_BALANCED). INVALID_ARGUMENT for an
// intent value this build does not know (the message names `intent` and
// the value) or ranking weights that are negative, not finite or all 0
// (the message names `ranking` and the term). O(1); thread-safe.
absl::StatusOr<tpr::index::TermWeights> ToTermWeights(
    const tpr::v1::SearchRequest& request);

// ToWireIntent returns the wire value of `intent`. O(1); thread-safe.
tpr::v1::Intent ToWireIntent(tpr::index::Intent intent);

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_CONVERT_H_
