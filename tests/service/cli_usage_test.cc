// What a new user of `tpr` meets, through the real binaries on loopback:
// ids and labels of `tpr add` (a subfolder added later gives the same ids,
// no empty label, --label, --id-prefix), two files for one id, content
// already indexed under another id, skipped files with their reason; the
// command line (unknown commands and options, help pages with an example,
// --version, exit codes); one message naming the service when one is down
// or is the wrong one; JSON errors and numbers.
#include <gtest/gtest.h>
#include <signal.h>

#include <filesystem>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "tests/service/extsvc_test_util.h"
#include "tpr/client.h"

namespace tpr::cli {
namespace {

using ::tpr::testing::CommandResult;
using ::tpr::testing::RunTpr;

int JsonInt(const std::string& json, const std::string& key) {
  static const std::regex kNumber(R"(^(-?\d+))");
  const size_t at = json.find("\"" + key + "\":");
  if (at == std::string::npos) return -1;
  std::smatch m;
  const std::string rest = json.substr(at + key.size() + 3);
  if (!std::regex_search(rest, m, kNumber)) return -2;  // not a number
  return std::stoi(m[1]);
}

int CountLines(const std::string& text, const std::string& prefix) {
  int n = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n'))
    n += absl::StartsWith(line, prefix);
  return n;
}

class CliUsageTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(cluster_.Start().ok()); }

  // A mesh of class `c` (0..) and pose `p`, as OFF text.
  std::string Mesh(int c, int p) {
    const std::string dir = absl::StrCat(cluster_.dir(), "/gen", c, "_", p);
    absl::StatusOr<std::vector<testing::GeneratedFile>> files =
        testing::GenerateSet(dir, c + 1, p + 1, 600);
    EXPECT_TRUE(files.ok()) << files.status();
    return files.ok() ? files->back().off : "";
  }
  void Write(const std::string& rel, const std::string& bytes) {
    testing::WriteFile(cluster_.dir() + "/" + rel, bytes);
  }
  std::string Path(const std::string& rel) {
    return cluster_.dir() + "/" + rel;
  }
  v1::Model Get(const std::string& id) {
    absl::StatusOr<client::IndexerClient> indexer =
        client::IndexerClient::Connect(cluster_.indexer().address());
    EXPECT_TRUE(indexer.ok());
    absl::StatusOr<v1::Model> m = indexer->Get(id);
    EXPECT_TRUE(m.ok()) << id << ": " << m.status();
    return m.ok() ? *m : v1::Model();
  }

  testing::Cluster cluster_;
};

TEST_F(CliUsageTest, ASubfolderAddedLaterGetsTheSameIdsAndNoLabelIsEmpty) {
  Write("library/dog1/T305.off", Mesh(0, 0));
  Write("library/dog1/T306.off", Mesh(0, 1));
  Write("library/cat/T400.off", Mesh(1, 0));
  Write("library/loose.off", Mesh(2, 0));
  CommandResult add = RunTpr(cluster_, "--json add " + Path("library"));
  ASSERT_EQ(add.exit_code, 0) << add.out << add.err;
  EXPECT_EQ(JsonInt(add.out, "added"), 4) << add.out;
  EXPECT_EQ(Get("dog1/T305.off").label(), "dog1");
  EXPECT_EQ(Get("cat/T400.off").label(), "cat");
  // A file directly in the folder given takes that folder's name.
  EXPECT_EQ(Get("library/loose.off").label(), "library");

  CommandResult sub = RunTpr(cluster_, "--json add " + Path("library/dog1/"));
  ASSERT_EQ(sub.exit_code, 0) << sub.out << sub.err;
  EXPECT_EQ(JsonInt(sub.out, "added"), 0) << sub.out;
  EXPECT_EQ(JsonInt(sub.out, "present"), 2) << sub.out;
  CommandResult stats = RunTpr(cluster_, "--json stats");
  EXPECT_EQ(JsonInt(stats.out, "models"), 4) << stats.out;

  // --label and --id-prefix say otherwise.
  CommandResult named = RunTpr(cluster_,
                               "--json add --label hound --id-prefix "
                               "shop/ --allow-duplicates " +
                                   Path("library/dog1"));
  ASSERT_EQ(named.exit_code, 0) << named.out << named.err;
  EXPECT_EQ(JsonInt(named.out, "added"), 2) << named.out;
  EXPECT_EQ(Get("shop/dog1/T306.off").label(), "hound");
}

TEST_F(CliUsageTest, SkippedFilesAreListedWithTheirReason) {
  Write("bad/dog/a.off", Mesh(0, 0));
  Write("bad/notes.txt", "not a mesh\n");
  Write("bad/dog.fbx", "binary\n");
  CommandResult add = RunTpr(cluster_, "add " + Path("bad"));
  ASSERT_EQ(add.exit_code, 0) << add.out << add.err;
  EXPECT_NE(add.out.find("1 mesh files: 1 added"), std::string::npos)
      << add.out;
  EXPECT_NE(add.out.find("skipped " + Path("bad/notes.txt") + ": not a mesh"),
            std::string::npos)
      << add.out;
  EXPECT_NE(add.out.find("skipped " + Path("bad/dog.fbx") + ": not a mesh"),
            std::string::npos)
      << add.out;
}

TEST_F(CliUsageTest, TwoFilesForOneIdAreRefusedNamingBoth) {
  Write("a/x/p.off", Mesh(0, 0));
  Write("b/x/p.off", Mesh(1, 0));
  CommandResult add = RunTpr(cluster_, "add " + Path("a") + " " + Path("b"));
  EXPECT_EQ(add.exit_code, 2) << add.out << add.err;
  EXPECT_NE(add.err.find(Path("a/x/p.off")), std::string::npos) << add.err;
  EXPECT_NE(add.err.find(Path("b/x/p.off")), std::string::npos) << add.err;
  EXPECT_NE(add.err.find("--id-prefix"), std::string::npos) << add.err;
  EXPECT_EQ(JsonInt(RunTpr(cluster_, "--json stats").out, "models"), 0);
}

TEST_F(CliUsageTest, SameNameInTwoFoldersGivesTwoIdsAndSameBytesAWarning) {
  // Different meshes named x.off in a/ and b/: both are added.
  Write("a/x.off", Mesh(0, 0));
  Write("b/x.off", Mesh(1, 0));
  CommandResult add =
      RunTpr(cluster_, "--json add " + Path("a") + " " + Path("b"));
  ASSERT_EQ(add.exit_code, 0) << add.out << add.err;
  EXPECT_EQ(JsonInt(add.out, "added"), 2) << add.out;
  Get("a/x.off");
  Get("b/x.off");

  // The same bytes under a new id: skipped, naming the id that holds them.
  Write("c/x.off", Mesh(0, 0));
  CommandResult dup = RunTpr(cluster_, "add " + Path("c"));
  EXPECT_EQ(dup.exit_code, 0) << dup.out << dup.err;
  EXPECT_NE(dup.out.find("same content as a/x.off"), std::string::npos)
      << dup.out;
  EXPECT_EQ(JsonInt(RunTpr(cluster_, "--json stats").out, "models"), 2);
  CommandResult allowed =
      RunTpr(cluster_, "--json add --allow-duplicates " + Path("c"));
  EXPECT_EQ(JsonInt(allowed.out, "added"), 1) << allowed.out;
  EXPECT_FALSE(Get("c/x.off").metadata().at("sha256").empty());
}

TEST_F(CliUsageTest, CommandLineMistakesAreNamedAndExit2) {
  CommandResult r = RunTpr(cluster_, "ad");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("did you mean 'add'?"), std::string::npos) << r.err;
  r = RunTpr(cluster_, "add --hepl");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("unknown option --hepl"), std::string::npos) << r.err;
  r = RunTpr(cluster_, "--version");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_TRUE(absl::StartsWith(r.out, "tpr 0.")) << r.out;
  r = RunTpr(cluster_, "query --id x -k 0");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  r = RunTpr(cluster_, "--indexer nonsense stats");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  r = RunTpr(cluster_, "help nosuch");
  EXPECT_EQ(r.exit_code, 2) << r.err;
}

TEST_F(CliUsageTest, EveryHelpPageHasAnExampleAndPlainWords) {
  CommandResult top = RunTpr(cluster_, "help");
  ASSERT_EQ(top.exit_code, 0) << top.err;
  EXPECT_NE(top.out.find("Example"), std::string::npos) << top.out;
  static const std::regex kCommand(R"(^  ([a-z]+) )");
  std::vector<std::string> commands;
  bool in_list = false;
  for (absl::string_view l : absl::StrSplit(top.out, '\n')) {
    const std::string line(l);
    if (line == "Subcommands:") in_list = true;
    if (in_list && line.empty()) break;
    std::smatch m;
    if (in_list && std::regex_search(line, m, kCommand))
      commands.push_back(m[1]);
  }
  ASSERT_GE(commands.size(), 10u) << top.out;
  for (const std::string& c : commands) {
    CommandResult page = RunTpr(cluster_, "help " + c);
    EXPECT_EQ(page.exit_code, 0) << c;
    EXPECT_NE(page.out.find("Example:\n  tpr "), std::string::npos) << c;
    for (const char* internal : {"Eq.", "ENUM", "value in {", "->", "TEXT:{"}) {
      EXPECT_EQ(page.out.find(internal), std::string::npos)
          << "tpr help " << c << " shows " << internal << ":\n"
          << page.out;
    }
    EXPECT_EQ(page.out, RunTpr(cluster_, c + " --help").out) << c;
  }
}

TEST_F(CliUsageTest, AServiceDownIsOneMessageNamingItAndHowToStartIt) {
  for (int i = 0; i < 6; ++i)
    Write(absl::StrCat("set/dog/", i, ".off"),
          Mesh(0, i % 2) + std::string(i, '\n'));
  cluster_.extractor(0).Stop(SIGTERM);
  const std::string address = cluster_.extractor(0).address();
  CommandResult add = RunTpr(cluster_, "add " + Path("set"));
  EXPECT_EQ(add.exit_code, 1) << add.out << add.err;
  EXPECT_EQ(CountLines(add.err, "tpr: "), 1) << add.err;
  EXPECT_NE(add.err.find("cannot reach tpr-extractor at " + address),
            std::string::npos)
      << add.err;
  EXPECT_NE(add.err.find("tpr-extractor --listen " + address),
            std::string::npos)
      << add.err;
  EXPECT_EQ(add.err.find("ConnectionOptions"), std::string::npos) << add.err;

  // --json: the error is one JSON object on stdout.
  CommandResult json = RunTpr(cluster_, "--json add " + Path("set"));
  EXPECT_EQ(json.exit_code, 1);
  EXPECT_TRUE(std::regex_search(
      json.out, std::regex(R"(^\{"error":\{"code":"UNAVAILABLE","message":")")))
      << json.out;
}

TEST_F(CliUsageTest, TheExtractorGivenAsIndexerIsNamed) {
  CommandResult r = RunTpr(
      cluster_, "--indexer " + cluster_.extractor(0).address() + " stats");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("is not a tpr-indexer"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("hint:"), std::string::npos) << r.err;
}

TEST_F(CliUsageTest, JsonNumbersAreNumbers) {
  CommandResult r = RunTpr(cluster_, "--json stats");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::regex_search(r.out, std::regex(R"("models":\d)"))) << r.out;
  EXPECT_TRUE(std::regex_search(r.out, std::regex(R"("disk_bytes":\d)")))
      << r.out;
}

}  // namespace
}  // namespace tpr::cli
