// The three signature converters (docs/architecture.md, "one converter per
// direction") agree: extractor -> indexer in-process
// (eval/lib/tpr_descriptor.h) gives exactly what the services give through
// the wire, extractor -> tpr.v1 (extractor/service/convert.h) then
// tpr.v1 -> indexer (indexer/service/convert.h), on extracted signatures of
// several generated shapes. A field added to one path and not the other
// fails here.
#include <gtest/gtest.h>

#include <string>

#include "eval/lib/tpr_descriptor.h"
#include "extractor/lib/extract.h"
#include "extractor/service/convert.h"
#include "extractor/synth/synth.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/metric.h"
#include "indexer/service/convert.h"

namespace tpr::eval {
namespace {

TEST(ConvertersTest, InProcessEqualsThroughTheWire) {
  synth::ShapeOptions shape;
  shape.target_vertices = 1500;
  shape.seed = 3;
  int compared = 0;
  for (const char* name : {"biped_adult", "quadruped_slender", "octopus"}) {
    absl::StatusOr<extract::Mesh> mesh = synth::GenerateShape(name, 1, shape);
    ASSERT_TRUE(mesh.ok()) << name << ": " << mesh.status();
    const extract::Options options;
    absl::StatusOr<extract::ExtractResult> r = extract::ExtractSignature(
        *mesh, extract::ComputeMeshStats(*mesh), options);
    ASSERT_TRUE(r.ok()) << name << ": " << r.status();
    ASSERT_FALSE(r->signature.features.empty()) << name;
    ASSERT_FALSE(r->signature.spectrum.empty()) << name;

    const index::Signature in_process = ToIndexSignature(r->signature);
    absl::StatusOr<index::Signature> wire = indexer::ToIndexSignature(
        extractor::SignatureToProto(r->signature, options));
    ASSERT_TRUE(wire.ok()) << name << ": " << wire.status();

    ASSERT_EQ(in_process.features.size(), wire->features.size()) << name;
    for (size_t i = 0; i < wire->features.size(); ++i) {
      const index::Feature& a = in_process.features[i];
      const index::Feature& b = wire->features[i];
      EXPECT_EQ(a.weight, b.weight) << name << " feature " << i;
      EXPECT_EQ(a.integral_geodesic, b.integral_geodesic)
          << name << " feature " << i;
      EXPECT_EQ(a.curvature, b.curvature) << name << " feature " << i;
      EXPECT_EQ(a.area, b.area) << name << " feature " << i;
      EXPECT_EQ(a.distance, b.distance) << name << " feature " << i;
    }
    EXPECT_EQ(in_process.spectrum, wire->spectrum) << name;

    // And so the metric cannot tell them apart.
    absl::StatusOr<index::PreparedSignature> pa =
        index::Prepare(in_process, index::GroundDistanceOptions{});
    absl::StatusOr<index::PreparedSignature> pb =
        index::Prepare(*wire, index::GroundDistanceOptions{});
    ASSERT_TRUE(pa.ok() && pb.ok()) << name;
    EXPECT_EQ(index::Distance(*pa, *pb, index::TermWeights{1, 1, 1}), 0.0)
        << name;
    ++compared;
  }
  EXPECT_EQ(compared, 3);
}

}  // namespace
}  // namespace tpr::eval
