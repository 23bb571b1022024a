// The indexer's one wire -> library converter and validator
// (indexer/service/convert.h): one test per documented rule, each checking
// the status code and that the message names the feature and field at
// fault; and the round trip through ToWireSignature.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/service/convert.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::indexer {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// A valid wire signature: 6 features x 4 bands from the test generator.
v1::Signature Valid() {
  index::testing::SignatureGeneratorOptions o;
  o.features = 6;
  o.bands = 4;
  o.feature_change = 0.0;
  index::testing::SignatureGenerator gen(o);
  return ToWireSignature(gen.Next(), 3);
}

// Expects INVALID_ARGUMENT for Valid() after `edit`, with every string of
// `names` in the message.
void ExpectInvalid(const std::function<void(v1::Signature*)>& edit,
                   const std::vector<std::string>& names) {
  v1::Signature s = Valid();
  edit(&s);
  absl::StatusOr<index::Signature> r = ToIndexSignature(s);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument)
      << r.status();
  for (const std::string& name : names) {
    EXPECT_NE(std::string(r.status().message()).find(name), std::string::npos)
        << "'" << name << "' not in: " << r.status().message();
  }
}

TEST(IndexerConvertTest, RoundTripIsExact) {
  index::testing::SignatureGeneratorOptions o;
  o.features = 30;
  o.bands = 20;
  index::testing::SignatureGenerator gen(o);
  for (int n = 0; n < 20; ++n) {
    const index::Signature s = gen.Next();
    const v1::Signature wire = ToWireSignature(s, 10);
    EXPECT_EQ(wire.options().bands(), 20);
    EXPECT_EQ(wire.features(9).kind(), v1::FEATURE_KIND_POINT);
    EXPECT_EQ(wire.features(10).kind(), v1::FEATURE_KIND_RING);
    absl::StatusOr<index::Signature> back = ToIndexSignature(wire);
    ASSERT_TRUE(back.ok()) << back.status();
    ASSERT_EQ(back->features.size(), s.features.size());
    for (size_t i = 0; i < s.features.size(); ++i) {
      const index::Feature& a = s.features[i];
      const index::Feature& b = back->features[i];
      EXPECT_EQ(a.weight, b.weight);
      EXPECT_EQ(a.integral_geodesic, b.integral_geodesic);
      EXPECT_EQ(a.curvature, b.curvature);
      EXPECT_EQ(a.area, b.area);
      EXPECT_EQ(a.distance, b.distance);
    }
  }
}

TEST(IndexerConvertTest, FeatureCount) {
  ExpectInvalid([](v1::Signature* s) { s->clear_features(); }, {"no feature"});
  v1::Signature big = Valid();
  while (big.features_size() <= index::kMaxFeatures)
    *big.add_features() = big.features(0);
  absl::StatusOr<index::Signature> r = ToIndexSignature(big);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kResourceExhausted);
}

TEST(IndexerConvertTest, BandCountMustBe1To256AndMatchTheVectors) {
  ExpectInvalid([](v1::Signature* s) { s->mutable_options()->set_bands(0); },
                {"options.bands", "1..256"});
  ExpectInvalid([](v1::Signature* s) { s->mutable_options()->set_bands(-3); },
                {"options.bands"});
  // 257 bands, vectors included: refused by the bound alone.
  ExpectInvalid(
      [](v1::Signature* s) {
        s->mutable_options()->set_bands(257);
        for (v1::Feature& f : *s->mutable_features()) {
          while (f.curvature_size() < 257) f.add_curvature(0.0);
          while (f.area_size() < 257) f.add_area(0.0);
          while (f.distance_size() < 257) f.add_distance(0.0);
        }
      },
      {"options.bands", "257"});
  // Vectors consistent with each other but not with options.bands.
  ExpectInvalid(
      [](v1::Signature* s) {
        for (v1::Feature& f : *s->mutable_features()) {
          f.add_curvature(0.0);
          f.add_area(0.0);
          f.add_distance(0.0);
        }
      },
      {"feature 0", "options.bands = 4"});
  // One vector of one feature too long (each of the three in turn).
  ExpectInvalid(
      [](v1::Signature* s) { s->mutable_features(2)->add_curvature(0.1); },
      {"feature 2", "curvature"});
  ExpectInvalid(
      [](v1::Signature* s) {
        s->mutable_features(3)->mutable_area()->RemoveLast();
      },
      {"feature 3", "area"});
  ExpectInvalid(
      [](v1::Signature* s) { s->mutable_features(5)->add_distance(0.1); },
      {"feature 5", "distance"});
}

TEST(IndexerConvertTest, KindMustBePointOrRing) {
  ExpectInvalid(
      [](v1::Signature* s) {
        s->mutable_features(1)->set_kind(v1::FEATURE_KIND_UNSPECIFIED);
      },
      {"feature 1", "kind"});
  ExpectInvalid(
      [](v1::Signature* s) {
        s->mutable_features(1)->set_kind(v1::FeatureKind(7));
      },
      {"feature 1", "kind"});
}

TEST(IndexerConvertTest, IntegralGeodesicInZeroOne) {
  for (double bad : {-1e-9, 1.0 + 1e-9, kNaN, kInf, -kInf}) {
    ExpectInvalid(
        [bad](v1::Signature* s) {
          s->mutable_features(4)->set_integral_geodesic(bad);
        },
        {"feature 4", "integral_geodesic"});
  }
  // The ends are valid.
  for (double good : {0.0, 1.0}) {
    v1::Signature s = Valid();
    s.mutable_features(4)->set_integral_geodesic(good);
    EXPECT_TRUE(ToIndexSignature(s).ok());
  }
}

TEST(IndexerConvertTest, WeightsNonNegativeFiniteAndSumToOne) {
  for (double bad : {-0.01, kNaN, kInf}) {
    ExpectInvalid(
        [bad](v1::Signature* s) { s->mutable_features(2)->set_weight(bad); },
        {"feature 2", "weight"});
  }
  ExpectInvalid(
      [](v1::Signature* s) {
        s->mutable_features(0)->set_weight(s->features(0).weight() + 0.3);
      },
      {"weights sum to", "must sum to 1"});
  // A zero weight is allowed (a feature with no mass).
  v1::Signature s = Valid();
  s.mutable_features(1)->set_weight(s.features(1).weight() +
                                    s.features(0).weight());
  s.mutable_features(0)->set_weight(0.0);
  EXPECT_TRUE(ToIndexSignature(s).ok()) << ToIndexSignature(s).status();
}

TEST(IndexerConvertTest, AreasInZeroOne) {
  for (double bad : {-1e-6, 1.5, kNaN, kInf}) {
    ExpectInvalid(
        [bad](v1::Signature* s) { s->mutable_features(3)->set_area(2, bad); },
        {"feature 3", "area[2]"});
  }
}

TEST(IndexerConvertTest, DistancesNonNegativeAndFinite) {
  for (double bad : {-1e-6, kNaN, kInf}) {
    ExpectInvalid(
        [bad](v1::Signature* s) {
          s->mutable_features(0)->set_distance(1, bad);
        },
        {"feature 0", "distance[1]"});
  }
}

TEST(IndexerConvertTest, CurvatureFiniteButMaySignChange) {
  for (double bad : {kNaN, kInf, -kInf}) {
    ExpectInvalid(
        [bad](v1::Signature* s) {
          s->mutable_features(5)->set_curvature(3, bad);
        },
        {"feature 5", "curvature[3]"});
  }
  // Saddle bands have negative curvature: valid.
  v1::Signature s = Valid();
  s.mutable_features(5)->set_curvature(3, -2.0);
  EXPECT_TRUE(ToIndexSignature(s).ok());
}

TEST(IndexerConvertTest, SpectrumCarriedAndValidated) {
  index::testing::SignatureGeneratorOptions o;
  o.features = 6;
  o.bands = 4;
  o.spectrum = 50;
  index::testing::SignatureGenerator gen(o);
  const index::Signature s = gen.Next();
  const v1::Signature wire = ToWireSignature(s, 3);
  EXPECT_EQ(wire.options().spectrum_eigenvalues(), 50);
  absl::StatusOr<index::Signature> back = ToIndexSignature(wire);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->spectrum, s.spectrum);

  auto expect = [&](const std::function<void(v1::Signature*)>& edit,
                    const std::string& name) {
    v1::Signature bad = wire;
    edit(&bad);
    absl::StatusOr<index::Signature> r = ToIndexSignature(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument)
        << r.status();
    EXPECT_NE(std::string(r.status().message()).find(name), std::string::npos)
        << r.status();
  };
  for (double bad : {0.0, -1.0, kNaN, kInf}) {
    expect([bad](v1::Signature* w) { w->set_spectrum(7, bad); }, "spectrum[7]");
  }
  expect([](v1::Signature* w) { w->set_spectrum(9, w->spectrum(8) * 0.5); },
         "ascending");
  expect([](v1::Signature* w) { w->add_spectrum(1e9); }, "at most 50");
  expect(
      [](v1::Signature* w) {
        w->mutable_options()->set_spectrum_eigenvalues(0);
        for (int i = 0; i < 1000; ++i) w->add_spectrum(1e9);
      },
      "at most 1000");
  // Unset spectrum_eigenvalues (the default) bounds only by 1000; an empty
  // spectrum is valid (a mesh too small for any eigenvalue).
  v1::Signature unset = wire;
  unset.mutable_options()->set_spectrum_eigenvalues(0);
  EXPECT_TRUE(ToIndexSignature(unset).ok());
  unset.clear_spectrum();
  EXPECT_TRUE(ToIndexSignature(unset).ok());
}

TEST(IndexerConvertTest, OtherSignatureVersionsAreFailedPrecondition) {
  for (int version : {0, 1, 2, kSignatureVersion + 1}) {
    v1::Signature s = Valid();
    s.set_signature_version(version);
    absl::StatusOr<index::Signature> r = ToIndexSignature(s);
    ASSERT_FALSE(r.ok()) << version;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kFailedPrecondition)
        << r.status();
    const std::string want =
        version < kSignatureVersion ? "tpr add --update" : "upgrade";
    EXPECT_NE(std::string(r.status().message()).find(want), std::string::npos)
        << r.status();
  }
}

// Found by fuzz_signature_convert: finite but huge band values (curvature
// 8e165, distance 1.3e240) were accepted, and their squared differences
// overflowed, so the EMD to any other signature was +inf. Values are now
// bounded by kMaxBandMagnitude, and the bound itself keeps the EMD finite.
TEST(IndexerConvertTest,
     HugeFiniteBandValuesAreRefusedAndTheBoundKeepsEmdFinite) {
  ExpectInvalid(
      [](v1::Signature* s) {
        s->mutable_features(2)->set_curvature(1, 8.0e165);
      },
      {"feature 2", "curvature[1]"});
  ExpectInvalid(
      [](v1::Signature* s) {
        s->mutable_features(2)->set_curvature(1, -8.0e165);
      },
      {"feature 2", "curvature[1]"});
  ExpectInvalid(
      [](v1::Signature* s) {
        s->mutable_features(4)->set_distance(0, 1.3e240);
      },
      {"feature 4", "distance[0]"});

  // The most extreme accepted signature, 256 bands at +-bound, against a
  // valid one of 256 bands at the other extreme.
  v1::Signature a = Valid();
  v1::Signature b = Valid();
  a.mutable_options()->set_bands(kMaxBands);
  b.mutable_options()->set_bands(kMaxBands);
  for (v1::Signature* s : {&a, &b}) {
    const double sign = s == &a ? 1.0 : -1.0;
    for (v1::Feature& f : *s->mutable_features()) {
      f.clear_curvature();
      f.clear_area();
      f.clear_distance();
      for (int i = 0; i < kMaxBands; ++i) {
        f.add_curvature(sign * kMaxBandMagnitude);
        f.add_area(s == &a ? 1.0 : 0.0);
        f.add_distance(s == &a ? kMaxBandMagnitude : 0.0);
      }
    }
  }
  absl::StatusOr<index::Signature> ia = ToIndexSignature(a);
  absl::StatusOr<index::Signature> ib = ToIndexSignature(b);
  ASSERT_TRUE(ia.ok()) << ia.status();
  ASSERT_TRUE(ib.ok()) << ib.status();
  const index::GroundDistanceOptions ground;
  const double d =
      index::Emd(*index::Prepare(*ia, ground), *index::Prepare(*ib, ground));
  EXPECT_TRUE(std::isfinite(d)) << d;
  EXPECT_GT(d, 0.0);
}

}  // namespace
}  // namespace tpr::indexer
