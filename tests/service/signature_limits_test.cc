// The signature contract's limits (common/signature_limits.h) hold alike in
// the extractor library (ExtractSignature's option check), the wire
// converter (OptionsFromProto) and the indexer's validator
// (ToIndexSignature): a value one accepts the others accept, a value one
// refuses the others refuse, so no signature is made that the indexer
// would refuse.
#include "common/signature_limits.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "extractor/lib/extract.h"
#include "extractor/service/convert.h"
#include "indexer/service/convert.h"
#include "tests/extractor/test_meshes.h"

namespace tpr::extractor {
namespace {

// LibraryAccepts returns whether ExtractSignature's option check passes
// `o` (the mesh is valid, so any other error is not about the options).
bool LibraryAccepts(const extract::Options& o) {
  const extract::Mesh mesh = testing::Icosphere(2);
  absl::StatusOr<extract::ExtractResult> r =
      extract::ExtractSignature(mesh, extract::ComputeMeshStats(mesh), o);
  return r.ok() || !absl::StartsWith(r.status().message(), "options:");
}

TEST(SignatureLimitsTest, BandsAgreeInLibraryConverterAndIndexer) {
  for (int bands : {1, 2, common::kMaxBands, common::kMaxBands + 1, 1000}) {
    extract::Options o;
    o.bands = bands;
    o.spectrum_eigenvalues = 0;
    const bool library = LibraryAccepts(o);
    v1::ExtractOptions wire;
    wire.set_bands(bands);
    const bool converter = OptionsFromProto(wire, 1).ok();
    EXPECT_EQ(library, common::BandsInRange(bands)) << bands;
    EXPECT_EQ(converter, common::BandsInRange(bands)) << bands;
  }
  // The indexer refuses a signature carrying more bands than the contract
  // allows, and accepts the largest count.
  for (int bands : {common::kMaxBands, common::kMaxBands + 1}) {
    index::Signature s;
    index::Feature f;
    f.weight = 1.0;
    f.integral_geodesic = 0.5;
    f.curvature.assign(bands, 0.0);
    f.area.assign(bands, 1.0 / bands);
    f.distance.assign(bands, 0.1);
    s.features.push_back(f);
    const v1::Signature wire = indexer::ToWireSignature(s, 1);
    EXPECT_EQ(indexer::ToIndexSignature(wire).ok(), common::BandsInRange(bands))
        << bands;
  }
}

TEST(SignatureLimitsTest, RingThresholdsAgreeInLibraryAndConverter) {
  for (double x : {0.0, 0.5, 0.999, 1.0, 1.5, -0.1}) {
    extract::Options paper;
    paper.ring_length_threshold = x;
    paper.spectrum_eigenvalues = 0;
    extract::Options persistence;
    persistence.ring_min_length = x;
    persistence.spectrum_eigenvalues = 0;
    v1::ExtractOptions wire_paper;
    wire_paper.set_ring_length_threshold(x);
    v1::ExtractOptions wire_persistence;
    wire_persistence.set_ring_min_length(x);
    const bool in_range = common::RingLengthInRange(x);
    EXPECT_EQ(LibraryAccepts(paper), in_range) << x;
    EXPECT_EQ(LibraryAccepts(persistence), in_range) << x;
    EXPECT_EQ(OptionsFromProto(wire_paper, 1).ok(), in_range) << x;
    EXPECT_EQ(OptionsFromProto(wire_persistence, 1).ok(), in_range) << x;
  }
  EXPECT_FALSE(common::RingLengthInRange(1.0));
  EXPECT_TRUE(common::RingLengthInRange(0.0));
}

TEST(SignatureLimitsTest, OneSignatureVersion) {
  // Both halves name the contract's one constant.
  EXPECT_EQ(&extractor::kSignatureVersion, &common::kSignatureVersion);
  EXPECT_EQ(&indexer::kSignatureVersion, &common::kSignatureVersion);
}

}  // namespace
}  // namespace tpr::extractor
