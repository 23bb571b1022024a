// The one dataset reader: folders of class subfolders and manifests, the
// order it keeps, and the errors it names (file and line).
#include "eval/lib/dataset.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace tpr::eval {
namespace {

namespace fs = std::filesystem;

class DatasetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string pattern =
        (fs::temp_directory_path() / "tpr-dataset-XXXXXX").string();
    ASSERT_NE(mkdtemp(pattern.data()), nullptr);
    root_ = pattern;
  }
  void TearDown() override { fs::remove_all(root_); }
  void Write(const std::string& relative, const std::string& text = "OFF\n") {
    const fs::path path = fs::path(root_) / relative;
    fs::create_directories(path.parent_path());
    std::ofstream(path) << text;
  }
  std::string root_;
};

TEST_F(DatasetTest, FolderGivesClassesFromSubfoldersSortedById) {
  Write("dog/b.off");
  Write("dog/a.OBJ");
  Write("cat/x/y.ply");
  Write("cat/readme.txt");  // not a mesh
  absl::StatusOr<std::vector<Item>> items = ReadDataset(root_);
  ASSERT_TRUE(items.ok()) << items.status();
  ASSERT_EQ(items->size(), 3u);
  EXPECT_EQ((*items)[0].id, "cat/x/y.ply");
  EXPECT_EQ((*items)[0].label, "x");  // the file's parent folder
  EXPECT_EQ((*items)[1].id, "dog/a.OBJ");
  EXPECT_EQ((*items)[1].label, "dog");
  EXPECT_EQ((*items)[2].path, (fs::path(root_) / "dog/b.off").string());
}

TEST_F(DatasetTest, MeshOutsideAClassFolderIsRefused) {
  Write("dog/a.off");
  Write("stray.off");
  absl::StatusOr<std::vector<Item>> items = ReadDataset(root_);
  ASSERT_FALSE(items.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(items.status()));
  EXPECT_NE(items.status().message().find("stray.off"),
            absl::string_view::npos);
}

TEST_F(DatasetTest, ManifestKeepsFileOrderAndSkipsComments) {
  Write("m/z.off");
  Write("m/a.off");
  Write("MANIFEST.txt", "# set\nm/z.off   zed extra\n\n\tm/./a.off\tay\n");
  absl::StatusOr<std::vector<Item>> items =
      ReadDataset(root_ + "/MANIFEST.txt");
  ASSERT_TRUE(items.ok()) << items.status();
  ASSERT_EQ(items->size(), 2u);
  EXPECT_EQ((*items)[0].id, "m/z.off");
  EXPECT_EQ((*items)[0].label, "zed");
  EXPECT_EQ((*items)[1].id, "m/a.off");  // normalized
  EXPECT_EQ((*items)[1].label, "ay");
}

TEST_F(DatasetTest, ManifestErrorsNameTheLine) {
  Write("a.off");
  Write("bad.txt", "a.off x\nlonely\n");
  absl::StatusOr<std::vector<Item>> bad = ReadDataset(root_ + "/bad.txt");
  ASSERT_TRUE(absl::IsInvalidArgument(bad.status())) << bad.status();
  EXPECT_NE(bad.status().message().find("bad.txt:2"), absl::string_view::npos);
  Write("missing.txt", "a.off x\nnone.off y\n");
  absl::StatusOr<std::vector<Item>> missing =
      ReadDataset(root_ + "/missing.txt");
  ASSERT_TRUE(absl::IsNotFound(missing.status())) << missing.status();
  EXPECT_NE(missing.status().message().find("missing.txt:2"),
            absl::string_view::npos);
  Write("twice.txt", "a.off x\n./a.off y\n");
  EXPECT_TRUE(
      absl::IsInvalidArgument(ReadDataset(root_ + "/twice.txt").status()));
  Write("empty.txt", "# nothing\n");
  EXPECT_TRUE(
      absl::IsInvalidArgument(ReadDataset(root_ + "/empty.txt").status()));
  EXPECT_TRUE(absl::IsNotFound(ReadDataset(root_ + "/nope").status()));
}

TEST_F(DatasetTest, ReadManifestLetsALaterLineWin) {
  Write("labels.txt", "a.off one\nb.off two\na.off three\n");
  absl::StatusOr<std::map<std::string, std::string>> labels =
      ReadManifest(root_ + "/labels.txt");
  ASSERT_TRUE(labels.ok());
  EXPECT_EQ(labels->at("a.off"), "three");
  EXPECT_EQ(labels->at("b.off"), "two");
}

TEST_F(DatasetTest, CollectItemsTakesFilesAsGivenAndFoldersRecursively) {
  Write("set/c/p.stl");
  Write("set/top.off");
  absl::StatusOr<std::vector<Item>> items =
      CollectItems({root_ + "/set", root_ + "/set/c/p.stl"});
  ASSERT_TRUE(items.ok());
  ASSERT_EQ(items->size(), 3u);
  EXPECT_EQ((*items)[0].id, "c/p.stl");
  EXPECT_EQ((*items)[1].id, "top.off");
  EXPECT_EQ((*items)[1].label, "");  // directly in the folder given
  EXPECT_EQ((*items)[2].label, "c");
  EXPECT_TRUE(absl::IsNotFound(CollectItems({root_ + "/none"}).status()));
}

}  // namespace
}  // namespace tpr::eval
