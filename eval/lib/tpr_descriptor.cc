#include "eval/lib/tpr_descriptor.h"

namespace tpr::eval {

index::Signature ToIndexSignature(const extract::Signature& signature) {
  index::Signature out;
  out.features.reserve(signature.features.size());
  for (const extract::Feature& f : signature.features) {
    out.features.push_back(
        {f.weight, f.integral_geodesic, f.curvature, f.area, f.distance});
  }
  out.spectrum = signature.spectrum;
  return out;
}

}  // namespace tpr::eval
