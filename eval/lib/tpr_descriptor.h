// The bridge from the extractor's signature to the indexer's, for in-process
// evaluation (the services do the same through tpr.v1.Signature).
//
//   index::Signature s = ToIndexSignature(result.signature);
//   auto prepared = index::Prepare(s, ground_options);
#ifndef TPR_EVAL_LIB_TPR_DESCRIPTOR_H_
#define TPR_EVAL_LIB_TPR_DESCRIPTOR_H_

#include "extractor/lib/signature.h"
#include "indexer/lib/signature.h"

namespace tpr::eval {

// ToIndexSignature copies weights, normalized integral geodesics, band
// vectors and the spectrum: the one extractor -> indexer converter for
// in-process evaluation (the services convert through tpr.v1.Signature:
// extractor/service/convert.h, indexer/service/convert.h).
// O(features x bands + spectrum). Thread-safe.
index::Signature ToIndexSignature(const extract::Signature& signature);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_TPR_DESCRIPTOR_H_
