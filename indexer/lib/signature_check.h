// The value ranges the signature contract (proto/tpr/v1/signature.proto)
// documents, checked on the library form: the one check every signature
// the indexer stores or compares passes, whether it arrived on the wire
// (indexer/service/convert.cc) or from the extractor in process
// (eval/lib/tpr_descriptor.cc).
//
//   if (absl::Status st = CheckSignatureContract(s, /*max_spectrum=*/50);
//       !st.ok()) return st;  // INVALID_ARGUMENT, names feature and field
#ifndef TPR_INDEXER_LIB_SIGNATURE_CHECK_H_
#define TPR_INDEXER_LIB_SIGNATURE_CHECK_H_

#include "absl/status/status.h"
#include "indexer/lib/signature.h"

namespace tpr::index {

// kMaxBandMagnitude bounds |curvature| and distance band values. Far beyond
// what a mesh gives (curvature bands are area-weighted curvature integrals,
// order 10-100; distances order 0.1), and small enough that the ground
// distance's sums of squared differences over 3 x common::kMaxBands bands
// stay finite: (2e15)^2 x 768 ~ 3e33. Without it a finite 1e200 made every
// EMD +inf (found by tests/fuzz fuzz_signature_convert).
inline constexpr double kMaxBandMagnitude = 1e15;

// CheckSignatureContract returns OK when every feature of `s` and its
// spectrum hold the contract's ranges; else INVALID_ARGUMENT whose message
// starts "signature " and names the feature index (or spectrum entry) and
// field at fault: band vectors of a length other than the first feature's
// curvature length (outside 1..common::kMaxBands), a weight negative or not
// finite, integral_geodesic outside [0, 1], a curvature or distance above
// kMaxBandMagnitude in magnitude or not finite, a negative distance, an
// area outside [0, 1], a spectrum longer than `max_spectrum`
// (options.spectrum_eigenvalues, at most kMaxSpectrum) or not ascending or
// holding a value that is not finite and > 0; then "malformed signature: "
// and ValidateSignature's message (no feature, too many, weights not
// summing to 1 within 1e-6, Eq. 6). Features are checked in order, each
// weight, integral_geodesic, curvature, area, distance in that order.
// O(features x bands); thread-safe.
absl::Status CheckSignatureContract(const Signature& s, int max_spectrum);

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_SIGNATURE_CHECK_H_
