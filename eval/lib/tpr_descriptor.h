// The bridge from the extractor's signature to the indexer's, for in-process
// evaluation. The services convert through tpr.v1.Signature; both routes end
// in the same check, tpr::index::CheckSignatureContract, so a signature the
// indexer would refuse is refused here too.
//
//   absl::StatusOr<index::Signature> s = ConvertSignature(result.signature);
//   if (s.ok()) prepared = index::Prepare(*s, ground_options);
#ifndef TPR_EVAL_LIB_TPR_DESCRIPTOR_H_
#define TPR_EVAL_LIB_TPR_DESCRIPTOR_H_

#include "absl/status/statusor.h"
#include "extractor/lib/signature.h"
#include "indexer/lib/signature.h"

namespace tpr::eval {

// ConvertSignature returns `signature`'s weights, normalized integral
// geodesics, band vectors and spectrum in the indexer's form, validated by
// tpr::index::CheckSignatureContract (INVALID_ARGUMENT naming the feature
// and field at fault). O(features x bands + spectrum). Thread-safe.
absl::StatusOr<index::Signature> ConvertSignature(
    const extract::Signature& signature);

// ToIndexSignature is ConvertSignature for a signature the extractor has
// just made, which holds the contract by construction: a failure is a
// broken invariant and aborts with the message on stderr.
index::Signature ToIndexSignature(const extract::Signature& signature);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_TPR_DESCRIPTOR_H_
