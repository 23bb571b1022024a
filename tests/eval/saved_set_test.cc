// SaveSet / LoadSet (eval/lib/saved_set.h): a round trip keeps every value
// bit for bit; malformed files are INVALID_ARGUMENT naming the line.
#include "eval/lib/saved_set.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "eval/lib/report.h"

namespace tpr::eval {
namespace {

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("saved_set_test_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

SavedSet Example() {
  SavedSet s;
  s.names = {"a/1.off", "a/2 with space.off", "b/3.off"};
  s.labels = {"a", "a", "b c"};
  s.spectra = {{2.0, 2.0000000000000004, 6.1}, {}, {1.0 / 3.0}};
  s.emd = DistanceMatrix(3);
  s.d2 = DistanceMatrix(3);
  s.emd.Set(0, 1, 0.1);
  s.emd.Set(0, 2, std::nextafter(1.0, 2.0));
  s.emd.Set(1, 2, 1e-300);
  s.d2.Set(0, 1, 3.0);
  s.d2.Set(0, 2, 0.0);
  s.d2.Set(1, 2, 12345.678);
  return s;
}

TEST(SavedSetTest, RoundTripIsExact) {
  const std::string path = TempPath("round");
  const SavedSet s = Example();
  ASSERT_TRUE(SaveSet(path, s).ok());
  absl::StatusOr<SavedSet> t = LoadSet(path);
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_EQ(t->names, s.names);
  EXPECT_EQ(t->labels, s.labels);
  EXPECT_EQ(t->spectra, s.spectra);
  for (size_t i = 0; i < 3; ++i) {
    for (size_t j = 0; j < 3; ++j) {
      EXPECT_EQ(t->emd(i, j), s.emd(i, j));
      EXPECT_EQ(t->d2(i, j), s.d2(i, j));
    }
  }
  std::filesystem::remove(path);
}

TEST(SavedSetTest, RefusesInconsistentSetsAndTabs) {
  SavedSet s = Example();
  s.labels.pop_back();
  EXPECT_TRUE(absl::IsInvalidArgument(SaveSet(TempPath("bad"), s)));
  s = Example();
  s.names[1] = "x\ty";
  EXPECT_TRUE(absl::IsInvalidArgument(SaveSet(TempPath("bad"), s)));
}

TEST(SavedSetTest, MissingFileIsNotFound) {
  EXPECT_TRUE(absl::IsNotFound(LoadSet(TempPath("absent")).status()));
}

TEST(SavedSetTest, MalformedFilesNameTheLine) {
  const std::string path = TempPath("malformed");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"something else\n", ":1:"},
      {"tpr-eval-matrices v1\nx\n", ":2:"},
      {"tpr-eval-matrices v1\n2\na\tb\nno tab\n", ":4:"},
      {"tpr-eval-matrices v1\n2\na\tx\nb\tx\n1 2\n1 nan\n", ":6:"},
      {"tpr-eval-matrices v1\n2\na\tx\nb\tx\n0\n0\n1 2\n",
       ":7:"},  // row of 2 for N = 2
      {"tpr-eval-matrices v1\n2\na\tx\nb\tx\n0\n0\n0.5\n",
       ":8:"},  // D2 missing
  };
  for (const auto& [text, where] : cases) {
    ASSERT_TRUE(WriteTextFile(path, text).ok());
    absl::StatusOr<SavedSet> t = LoadSet(path);
    ASSERT_FALSE(t.ok()) << text;
    EXPECT_TRUE(absl::IsInvalidArgument(t.status())) << t.status();
    EXPECT_NE(t.status().message().find(where), absl::string_view::npos)
        << t.status() << " for " << text;
  }
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace tpr::eval
