#include "eval/lib/tpr_descriptor.h"

#include <cstdio>
#include <cstdlib>
#include <string>

#include "indexer/lib/signature_check.h"

namespace tpr::eval {

absl::StatusOr<index::Signature> ConvertSignature(
    const extract::Signature& signature) {
  index::Signature out;
  out.features.reserve(signature.features.size());
  for (const extract::Feature& f : signature.features) {
    out.features.push_back(
        {f.weight, f.integral_geodesic, f.curvature, f.area, f.distance});
  }
  out.spectrum = signature.spectrum;
  // The spectrum's length bound is the contract's (the extractor's
  // options are not part of extract::Signature).
  if (absl::Status st = index::CheckSignatureContract(out, 0); !st.ok()) {
    return st;
  }
  return out;
}

index::Signature ToIndexSignature(const extract::Signature& signature) {
  absl::StatusOr<index::Signature> out = ConvertSignature(signature);
  if (!out.ok()) {
    std::fprintf(stderr, "extractor signature breaks the contract: %s\n",
                 std::string(out.status().message()).c_str());
    std::abort();
  }
  return *std::move(out);
}

}  // namespace tpr::eval
