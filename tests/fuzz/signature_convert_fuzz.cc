// libFuzzer target: the indexer's wire-to-library signature conversion
// (bytes -> tpr.v1.Signature -> ToIndexSignature -> Prepare -> EMD).
//
// Oracle: a signature the converter accepts must be matchable: Prepare
// succeeds, the EMD to itself is 0 (up to rounding) and the EMD to a fixed
// valid signature is finite, non-negative and symmetric. A refusal must be
// INVALID_ARGUMENT, RESOURCE_EXHAUSTED or FAILED_PRECONDITION (another
// signature_version) with a message. Protobuf's parser
// sees the raw bytes, so the corpus is serialized tpr.v1.Signature messages.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>

#include "absl/status/status.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/service/convert.h"
#include "tests/fuzz/fuzz_check.h"
#include "tpr/v1/signature.pb.h"

namespace {

// A valid two-feature signature (weights sum to 1, 4 bands).
tpr::index::Signature Reference() {
  // Positional (weight, integral geodesic, curvature, area, distance bands).
  tpr::index::Signature s;
  s.features.push_back({0.7,
                        0.2,
                        {0.1, 0.2, 0.3, 0.4},
                        {0.25, 0.25, 0.25, 0.25},
                        {0.1, 0.1, 0.2, 0.2}});
  s.features.push_back({0.3,
                        0.7,
                        {0.4, 0.1, 0.0, 0.2},
                        {0.4, 0.3, 0.2, 0.1},
                        {0.2, 0.1, 0.1, 0.3}});
  return s;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tpr::v1::Signature wire;
  if (!wire.ParseFromArray(data, static_cast<int>(size))) return 0;
  absl::StatusOr<tpr::index::Signature> converted =
      tpr::indexer::ToIndexSignature(wire);
  if (!converted.ok()) {
    tpr::fuzz::CheckRefusal(converted.status(),
                            {absl::StatusCode::kInvalidArgument,
                             absl::StatusCode::kResourceExhausted,
                             absl::StatusCode::kFailedPrecondition});
    return 0;
  }
  const tpr::index::GroundDistanceOptions ground;
  absl::StatusOr<tpr::index::PreparedSignature> p =
      tpr::index::Prepare(*converted, ground);
  FUZZ_CHECK(p.ok(), "an accepted signature can be prepared");
  static const tpr::index::PreparedSignature reference =
      *tpr::index::Prepare(Reference(), ground);
  const double self = tpr::index::Emd(*p, *p);
  FUZZ_CHECK(std::isfinite(self) && std::abs(self) <= 1e-6, "EMD(s, s) == 0");
  if (p->bands() == reference.bands()) {
    const double d = tpr::index::Emd(*p, reference);
    const double back = tpr::index::Emd(reference, *p);
    if (!(std::isfinite(d) && d >= 0)) std::fprintf(stderr, "EMD = %.17g\n", d);
    FUZZ_CHECK(std::isfinite(d) && d >= 0,
               "EMD to a valid signature is finite, >= 0");
    FUZZ_CHECK(std::abs(d - back) <= 1e-6 * (1 + d), "EMD is symmetric");
  }
  return 0;
}
