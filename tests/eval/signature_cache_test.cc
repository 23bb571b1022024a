// The evaluation's signature cache (eval/lib/signature_cache.h): a stored
// description reads back exactly, spectrum included; another key, a
// truncated file or a missing one is a miss.
#include "eval/lib/signature_cache.h"

#include <gtest/gtest.h>
#include <stdlib.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace tpr::eval {
namespace {

TEST(SignatureCacheTest, RoundTripIncludingSpectrumAndMisses) {
  std::string pattern =
      (std::filesystem::temp_directory_path() / "tpr-cache-test.XXXXXX")
          .string();
  ASSERT_NE(mkdtemp(pattern.data()), nullptr);
  const std::string dir = pattern;
  CachedDescription d;
  d.signature.features.push_back(
      {0.25, 0.5, {1.0 / 3, -2.0}, {0.1, 0.2}, {0.3, 0.4}});
  d.signature.features.push_back(
      {0.75, 1.0, {0.0, 1e-300}, {0.0, 1.0}, {2.5, 0.0}});
  d.signature.spectrum = {2.0000000000000004, 2.1, 6.0, 1e5};
  d.points = 1;
  d.rings = 1;
  d.vertices = 1234;
  d.faces = 2460;
  d.d2 = {0.5, 0.25, 0.25};
  d.extract_ms = 12.5;
  d.stage_ms = {{"spectrum", 3.25}, {"intake", 1.0}};
  ASSERT_TRUE(StoreCached(dir, "key one", d));

  CachedDescription back;
  ASSERT_TRUE(LoadCached(dir, "key one", &back));
  ASSERT_EQ(back.signature.features.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    const index::Feature& a = d.signature.features[i];
    const index::Feature& b = back.signature.features[i];
    EXPECT_EQ(a.weight, b.weight);
    EXPECT_EQ(a.integral_geodesic, b.integral_geodesic);
    EXPECT_EQ(a.curvature, b.curvature);
    EXPECT_EQ(a.area, b.area);
    EXPECT_EQ(a.distance, b.distance);
  }
  EXPECT_EQ(back.signature.spectrum, d.signature.spectrum);
  EXPECT_EQ(back.points, 1);
  EXPECT_EQ(back.rings, 1);
  EXPECT_EQ(back.vertices, 1234);
  EXPECT_EQ(back.faces, 2460);
  EXPECT_EQ(back.d2, d.d2);
  EXPECT_EQ(back.extract_ms, 12.5);
  EXPECT_EQ(back.stage_ms, d.stage_ms);

  CachedDescription miss;
  EXPECT_FALSE(LoadCached(dir, "key two", &miss));
  // A truncated entry is a miss, not garbage.
  const std::filesystem::path file =
      std::filesystem::path(dir) / CacheFileName("key one");
  std::filesystem::resize_file(file, std::filesystem::file_size(file) - 12);
  EXPECT_FALSE(LoadCached(dir, "key one", &miss));
  std::filesystem::remove_all(dir);
}

// Format v1 (no vertex and face counts) is no longer read: an entry in it,
// key and all, is a miss; the same entry in v2 (counts, no spectrum) reads.
TEST(SignatureCacheTest, VersionOneEntryIsAMissVersionTwoReads) {
  std::string pattern =
      (std::filesystem::temp_directory_path() / "tpr-cache-test.XXXXXX")
          .string();
  ASSERT_NE(mkdtemp(pattern.data()), nullptr);
  const std::string dir = pattern;
  const std::filesystem::path file =
      std::filesystem::path(dir) / CacheFileName("k");
  const std::string body = "1\n0.5 0.25\n1 1\n1 4\n1 5\nend\n";
  {
    std::ofstream out(file);
    out << "tpr-eval-cache-v1\nk\n1 0 7.5 0\n1 0.5\n" << body;
  }
  CachedDescription d;
  EXPECT_FALSE(LoadCached(dir, "k", &d));
  {
    std::ofstream out(file);
    out << "tpr-eval-cache-v2\nk\n1 0 7.5 0 10 16\n1 0.5\n" << body;
  }
  ASSERT_TRUE(LoadCached(dir, "k", &d));
  EXPECT_EQ(d.vertices, 10);
  EXPECT_EQ(d.faces, 16);
  ASSERT_EQ(d.signature.features.size(), 1u);
  EXPECT_EQ(d.signature.features[0].weight, 0.5);
  EXPECT_EQ(d.signature.features[0].distance, (std::vector<double>{5}));
  EXPECT_TRUE(d.signature.spectrum.empty());
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace tpr::eval
