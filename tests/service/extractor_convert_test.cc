// OptionsFromProto / OptionsToProto (extractor/service/convert.h): every
// wire option reaches the library, zero means the library's documented
// default, and a value out of range is INVALID_ARGUMENT naming the field.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "extractor/lib/extract.h"
#include "extractor/service/convert.h"

namespace tpr::extractor {
namespace {

TEST(ExtractorConvertTest, ZeroFieldsGiveTheLibraryDefaults) {
  absl::StatusOr<extract::Options> o =
      OptionsFromProto(v1::ExtractOptions(), 4);
  ASSERT_TRUE(o.ok()) << o.status();
  const extract::Options defaults;
  EXPECT_EQ(o->bands, defaults.bands);
  EXPECT_EQ(o->cycle_min_vertices, defaults.cycle_min_vertices);
  EXPECT_EQ(o->ring_length_threshold, defaults.ring_length_threshold);
  EXPECT_EQ(o->spectrum_eigenvalues, defaults.spectrum_eigenvalues);
  EXPECT_EQ(o->spectrum_eigenvalues, 50);
  EXPECT_EQ(o->point_min_prominence, defaults.point_min_prominence);
  EXPECT_EQ(o->cut_handles, defaults.cut_handles);
  EXPECT_TRUE(o->cut_handles);
  EXPECT_EQ(o->topology, extract::TopologyMethod::kPersistence);
  EXPECT_EQ(o->ring_min_length, defaults.ring_min_length);
  EXPECT_GT(o->point_min_prominence, 0.0);
}

TEST(ExtractorConvertTest, EveryFieldIsMapped) {
  v1::ExtractOptions p;
  p.set_bands(12);
  p.set_cycle_min_vertices(3);
  p.set_ring_length_threshold(0.07);
  p.set_threads(2);
  p.set_explain(true);
  p.set_spectrum_eigenvalues(17);
  p.set_point_min_prominence(0.02);
  p.set_handles(v1::HANDLE_TREATMENT_KEEP);
  p.set_topology(v1::TOPOLOGY_METHOD_PAPER);
  p.set_ring_min_length(0.03);
  absl::StatusOr<extract::Options> o = OptionsFromProto(p, 4);
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->topology, extract::TopologyMethod::kPaper);
  EXPECT_EQ(o->ring_min_length, 0.03);
  EXPECT_EQ(o->bands, 12);
  EXPECT_EQ(o->cycle_min_vertices, 3);
  EXPECT_EQ(o->ring_length_threshold, 0.07);
  EXPECT_EQ(o->threads, 2);
  EXPECT_TRUE(o->explain);
  EXPECT_EQ(o->spectrum_eigenvalues, 17);
  EXPECT_EQ(o->point_min_prominence, 0.02);
  EXPECT_FALSE(o->cut_handles);
  // And back: the wire form records what was used, field for field.
  const v1::ExtractOptions back = OptionsToProto(*o);
  EXPECT_EQ(back.bands(), 12);
  EXPECT_EQ(back.cycle_min_vertices(), 3);
  EXPECT_EQ(back.ring_length_threshold(), 0.07);
  EXPECT_EQ(back.threads(), 2);
  EXPECT_TRUE(back.explain());
  EXPECT_EQ(back.spectrum_eigenvalues(), 17);
  EXPECT_EQ(back.point_min_prominence(), 0.02);
  EXPECT_EQ(back.handles(), v1::HANDLE_TREATMENT_KEEP);
  EXPECT_EQ(back.topology(), v1::TOPOLOGY_METHOD_PAPER);
  EXPECT_EQ(back.ring_min_length(), 0.03);
}

TEST(ExtractorConvertTest, TopologyMethodsMapBothWays) {
  v1::ExtractOptions p;
  p.set_topology(v1::TOPOLOGY_METHOD_PERSISTENCE);
  absl::StatusOr<extract::Options> persistence = OptionsFromProto(p, 4);
  ASSERT_TRUE(persistence.ok()) << persistence.status();
  EXPECT_EQ(persistence->topology, extract::TopologyMethod::kPersistence);
  EXPECT_EQ(OptionsToProto(*persistence).topology(),
            v1::TOPOLOGY_METHOD_PERSISTENCE);
  p.set_topology(v1::TOPOLOGY_METHOD_PAPER);
  absl::StatusOr<extract::Options> paper = OptionsFromProto(p, 4);
  ASSERT_TRUE(paper.ok()) << paper.status();
  EXPECT_EQ(paper->topology, extract::TopologyMethod::kPaper);
  EXPECT_EQ(OptionsToProto(*paper).topology(), v1::TOPOLOGY_METHOD_PAPER);
}

TEST(ExtractorConvertTest, HandleTreatmentsMapBothWays) {
  v1::ExtractOptions p;
  p.set_handles(v1::HANDLE_TREATMENT_CUT);
  absl::StatusOr<extract::Options> cut = OptionsFromProto(p, 4);
  ASSERT_TRUE(cut.ok()) << cut.status();
  EXPECT_TRUE(cut->cut_handles);
  EXPECT_EQ(OptionsToProto(*cut).handles(), v1::HANDLE_TREATMENT_CUT);
  p.set_handles(v1::HANDLE_TREATMENT_KEEP);
  absl::StatusOr<extract::Options> keep = OptionsFromProto(p, 4);
  ASSERT_TRUE(keep.ok()) << keep.status();
  EXPECT_FALSE(keep->cut_handles);
  EXPECT_EQ(OptionsToProto(*keep).handles(), v1::HANDLE_TREATMENT_KEEP);
}

TEST(ExtractorConvertTest, DefaultsAreFilledInTheWireForm) {
  const v1::ExtractOptions back =
      OptionsToProto(*OptionsFromProto(v1::ExtractOptions(), 4));
  EXPECT_EQ(back.spectrum_eigenvalues(), 50);
  EXPECT_EQ(back.bands(), extract::Options().bands);
  // The stored signature says which treatment made it, never "unspecified".
  EXPECT_EQ(back.handles(), v1::HANDLE_TREATMENT_CUT);
  EXPECT_EQ(back.topology(), v1::TOPOLOGY_METHOD_PERSISTENCE);
  EXPECT_EQ(back.point_min_prominence(),
            extract::Options().point_min_prominence);
  EXPECT_EQ(back.ring_min_length(), extract::Options().ring_min_length);
}

TEST(ExtractorConvertTest, ThreadsAreCappedByTheServer) {
  v1::ExtractOptions p;
  p.set_threads(64);
  EXPECT_EQ(OptionsFromProto(p, 3)->threads, 3);
}

void ExpectInvalid(const v1::ExtractOptions& p, const std::string& field) {
  absl::StatusOr<extract::Options> o = OptionsFromProto(p, 4);
  ASSERT_FALSE(o.ok()) << field;
  EXPECT_TRUE(absl::IsInvalidArgument(o.status())) << o.status();
  EXPECT_NE(o.status().message().find("options." + field),
            absl::string_view::npos)
      << o.status();
}

TEST(ExtractorConvertTest, OutOfRangeValuesNameTheField) {
  v1::ExtractOptions p;
  p.set_spectrum_eigenvalues(-1);
  ExpectInvalid(p, "spectrum_eigenvalues");
  p.set_spectrum_eigenvalues(1001);
  ExpectInvalid(p, "spectrum_eigenvalues");
  p = v1::ExtractOptions();
  p.set_point_min_prominence(-0.1);
  ExpectInvalid(p, "point_min_prominence");
  p.set_point_min_prominence(std::numeric_limits<double>::quiet_NaN());
  ExpectInvalid(p, "point_min_prominence");
  p.set_point_min_prominence(1.5);
  ExpectInvalid(p, "point_min_prominence");
  p = v1::ExtractOptions();
  p.set_ring_min_length(-0.1);
  ExpectInvalid(p, "ring_min_length");
  p.set_ring_min_length(std::numeric_limits<double>::quiet_NaN());
  ExpectInvalid(p, "ring_min_length");
  p.set_ring_min_length(1.0);
  ExpectInvalid(p, "ring_min_length");
  p = v1::ExtractOptions();
  p.set_topology(static_cast<v1::TopologyMethod>(7));
  ExpectInvalid(p, "topology");
  p = v1::ExtractOptions();
  p.set_bands(257);
  ExpectInvalid(p, "bands");
  p = v1::ExtractOptions();
  p.set_ring_length_threshold(1.0);
  ExpectInvalid(p, "ring_length_threshold");
  p = v1::ExtractOptions();
  p.set_cycle_min_vertices(-2);
  ExpectInvalid(p, "cycle_min_vertices");
  // A value from a newer contract (proto3 keeps unknown enum numbers).
  p = v1::ExtractOptions();
  p.set_handles(static_cast<v1::HandleTreatment>(7));
  ExpectInvalid(p, "handles");
}

TEST(ExtractorConvertTest, LimitsAreAccepted) {
  v1::ExtractOptions p;
  p.set_spectrum_eigenvalues(1000);
  p.set_point_min_prominence(1.0);
  absl::StatusOr<extract::Options> o = OptionsFromProto(p, 4);
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->spectrum_eigenvalues, 1000);
  p.set_spectrum_eigenvalues(1);
  EXPECT_EQ(OptionsFromProto(p, 4)->spectrum_eigenvalues, 1);
}

}  // namespace
}  // namespace tpr::extractor
