// The limits of the signature contract (proto/tpr/v1/signature.proto),
// each defined once with the one rule that tests it. The extractor's option
// checks (extractor/lib/extract.cc, extractor/service/convert.cc), the
// indexer's signature validator (indexer/service/convert.cc) and the
// evaluation's bridge (eval/lib/tpr_descriptor.cc) all test against these,
// so the two halves cannot disagree. Header-only, no dependency: the pure
// libraries may include it.
//
//   if (!common::BandsInRange(options.bands)) {
//     return absl::InvalidArgumentError("bands not in [1, 256]");
//   }
#ifndef TPR_COMMON_SIGNATURE_LIMITS_H_
#define TPR_COMMON_SIGNATURE_LIMITS_H_

namespace tpr::common {

// kSignatureVersion is the Signature.signature_version the extractor stamps
// into every signature and the only one the indexer compares: 3, TPR
// features plus a Laplace-Beltrami spectrum (signature.proto describes the
// versions).
inline constexpr int kSignatureVersion = 3;

// kMinBands and kMaxBands bound ExtractOptions.bands, the length of every
// band vector of a signature: 1..256.
inline constexpr int kMinBands = 1;
inline constexpr int kMaxBands = 256;

// BandsInRange returns whether `bands` is in kMinBands..kMaxBands.
constexpr bool BandsInRange(int bands) {
  return bands >= kMinBands && bands <= kMaxBands;
}

// kMaxSpectrumEigenvalues bounds ExtractOptions.spectrum_eigenvalues and the
// length of Signature.spectrum: 1000.
inline constexpr int kMaxSpectrumEigenvalues = 1000;

// SpectrumEigenvaluesInRange returns whether `count` is in
// 0..kMaxSpectrumEigenvalues (0 skips the spectrum in the library and means
// the default on the wire).
constexpr bool SpectrumEigenvaluesInRange(int count) {
  return count >= 0 && count <= kMaxSpectrumEigenvalues;
}

// RingLengthInRange returns whether a ring threshold (ring_length_threshold,
// ring_min_length) is in [0, 1): a ring is a region whose length exceeds
// this fraction, so 1 or more would refuse every ring. False for NaN.
constexpr bool RingLengthInRange(double fraction) {
  return fraction >= 0.0 && fraction < 1.0;
}

// ProminenceInRange returns whether point_min_prominence is in [0, 1].
// False for NaN.
constexpr bool ProminenceInRange(double fraction) {
  return fraction >= 0.0 && fraction <= 1.0;
}

}  // namespace tpr::common

#endif  // TPR_COMMON_SIGNATURE_LIMITS_H_
