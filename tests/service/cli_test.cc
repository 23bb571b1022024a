// The `tpr` command end to end: both service binaries on loopback, a
// generated labelled folder added through `tpr add`, `tpr query --json`
// streams compared with an in-process brute-force EMD ranking of the
// signatures the indexer returns; re-runs, failures, get/list/stats/remove;
// SIGTERM during a search stream.
#include <gtest/gtest.h>
#include <signal.h>
#include <stdio.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>

#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "tests/service/extsvc_test_util.h"
#include "tpr/client.h"

namespace tpr::cli {
namespace {

using ::tpr::testing::Ranked;

using ::tpr::testing::CommandResult;
using ::tpr::testing::RunTpr;

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::stringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) lines.push_back(line);
  }
  return lines;
}

// Parses one `tpr query --json` line.
bool ParseNeighbor(const std::string& line, int* rank, std::string* id,
                   std::string* label, double* distance) {
  static const std::regex kLine(
      R"re(^\{"rank":(\d+),"id":"([^"]*)","label":"([^"]*)",)re"
      R"re("distance":([-+0-9.eE]+)\}$)re");
  std::smatch m;
  if (!std::regex_match(line, m, kLine)) return false;
  *rank = std::stoi(m[1]);
  *id = m[2];
  *label = m[3];
  *distance = std::stod(m[4]);
  return true;
}

// ParseRanking appends every line of `tpr --json query` output to `ranked`
// as (distance, id); returns the first line that is not a neighbour, or ""
// when every line is one.
std::string ParseRanking(const std::string& out, std::vector<Ranked>* ranked) {
  for (const std::string& line : Lines(out)) {
    int rank;
    std::string id, label;
    double distance;
    if (!ParseNeighbor(line, &rank, &id, &label, &distance)) return line;
    ranked->push_back({distance, id});
  }
  return "";
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

// The id `tpr add FILE` gives: "<its folder's name>/<its name>".
std::string FileId(const std::string& path) {
  const std::filesystem::path p(path);
  return p.parent_path().filename().string() + "/" + p.filename().string();
}

int JsonInt(const std::string& json, const std::string& key) {
  const size_t at = json.find("\"" + key + "\":");
  if (at == std::string::npos) return -1;
  size_t start = at + key.size() + 3;
  if (json[start] == '"') ++start;  // protobuf's JSON prints int64 as a string
  return std::atoi(json.c_str() + start);
}

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(cluster_.Start().ok()); }
  testing::Cluster cluster_;
};

TEST_F(CliTest, AddThenQueryStreamsTheBruteForceRanking) {
  const std::string set = cluster_.dir() + "/set";
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(set, 3, 2, 1500);
  ASSERT_TRUE(files.ok()) << files.status();
  testing::WriteFile(set + "/broken/bad.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n");

  // One bad file: the others are still indexed, the failure is reported
  // with its reason, and the exit code says something failed.
  CommandResult add = RunTpr(cluster_, "--json add --jobs 3 " + set);
  EXPECT_EQ(add.exit_code, 1) << add.err;
  EXPECT_EQ(JsonInt(add.out, "added"), 6) << add.out;
  EXPECT_EQ(JsonInt(add.out, "failed"), 1) << add.out;
  EXPECT_NE(add.out.find("broken/bad.off"), std::string::npos) << add.out;
  EXPECT_NE(add.out.find("INVALID_ARGUMENT"), std::string::npos) << add.out;

  // Re-running skips what is there; --update replaces it.
  CommandResult again = RunTpr(cluster_, "--json add " + set);
  EXPECT_EQ(JsonInt(again.out, "skipped"), 6) << again.out;
  EXPECT_EQ(JsonInt(again.out, "added"), 0) << again.out;
  CommandResult update = RunTpr(cluster_, "--json add --update " + set);
  EXPECT_EQ(JsonInt(update.out, "updated"), 6) << update.out;

  // The oracle ranks the signatures the indexer holds.
  absl::StatusOr<client::IndexerClient> indexer =
      client::IndexerClient::Connect(cluster_.indexer().address());
  ASSERT_TRUE(indexer.ok());
  std::vector<std::pair<std::string, v1::Signature>> models;
  std::map<std::string, std::string> labels;
  for (const testing::GeneratedFile& f : *files) {
    absl::StatusOr<v1::Model> m = indexer->Get(f.relative_path);
    ASSERT_TRUE(m.ok()) << f.relative_path << ": " << m.status();
    EXPECT_EQ(m->label(), f.label);  // label from the parent folder
    models.emplace_back(m->id(), m->signature());
    labels[m->id()] = m->label();
  }
  for (const auto& [id, signature] : models) {
    CommandResult q = RunTpr(cluster_, "--json query -k 6 --id " + id);
    ASSERT_EQ(q.exit_code, 0) << q.err;
    std::vector<Ranked> streamed;
    for (const std::string& line : Lines(q.out)) {
      int rank;
      std::string got_id, label;
      double distance;
      ASSERT_TRUE(ParseNeighbor(line, &rank, &got_id, &label, &distance))
          << line;
      EXPECT_EQ(rank, static_cast<int>(streamed.size()) + 1);
      EXPECT_EQ(label, labels[got_id]);
      streamed.push_back({distance, got_id});
    }
    absl::StatusOr<std::vector<Ranked>> expected =
        testing::BruteForceRanking(signature, models);
    ASSERT_TRUE(expected.ok()) << expected.status();
    ASSERT_EQ(streamed.size(), 6u);
    EXPECT_EQ(testing::SameRanking(streamed, *expected), "") << "query " << id;
  }

  // --rank-by: the paper's EMD alone and the spectrum alone, over every
  // model, against the brute force under that distance.
  {
    const auto& [id, signature] = models.front();
    const std::pair<const char*,
                    std::function<double(const index::PreparedSignature&,
                                         const index::PreparedSignature&)>>
        rankings[] = {{"paper",
                       [](const index::PreparedSignature& a,
                          const index::PreparedSignature& b) {
                         return index::Emd(a, b);
                       }},
                      {"spectrum", [](const index::PreparedSignature& a,
                                      const index::PreparedSignature& b) {
                         return index::SpectralDistance(a, b);
                       }}};
    for (const auto& [name, distance] : rankings) {
      CommandResult q = RunTpr(
          cluster_,
          absl::StrCat("--json query -k 6 --rank-by ", name, " --id ", id));
      ASSERT_EQ(q.exit_code, 0) << q.err;
      std::vector<Ranked> streamed;
      ASSERT_EQ(ParseRanking(q.out, &streamed), "");
      absl::StatusOr<std::vector<Ranked>> expected =
          testing::BruteForceRanking(signature, models, distance);
      ASSERT_TRUE(expected.ok()) << expected.status();
      ASSERT_EQ(streamed.size(), 6u);
      EXPECT_EQ(testing::SameRanking(streamed, *expected), "") << name;
    }
    EXPECT_EQ(RunTpr(cluster_, "query --rank-by nonsense --id " + id).exit_code,
              2);
  }

  // --intent: each intent against the brute force under its weighting.
  {
    const auto& [id, signature] = models.front();
    for (const auto& [name, intent] :
         {std::pair<const char*, index::Intent>{"identity",
                                                index::Intent::kIdentity},
          {"KIND", index::Intent::kKind},
          {"balanced", index::Intent::kBalanced}}) {
      CommandResult q = RunTpr(
          cluster_,
          absl::StrCat("--json query -k 6 --intent ", name, " --id ", id));
      ASSERT_EQ(q.exit_code, 0) << q.err;
      std::vector<Ranked> streamed;
      ASSERT_EQ(ParseRanking(q.out, &streamed), "");
      const index::TermWeights w = index::IntentWeights(intent);
      absl::StatusOr<std::vector<Ranked>> expected =
          testing::BruteForceRanking(signature, models,
                                     [w](const index::PreparedSignature& a,
                                         const index::PreparedSignature& b) {
                                       return index::Distance(a, b, w);
                                     });
      ASSERT_TRUE(expected.ok()) << expected.status();
      ASSERT_EQ(streamed.size(), 6u);
      EXPECT_EQ(testing::SameRanking(streamed, *expected), "") << name;
    }
    CommandResult bad = RunTpr(cluster_, "query --intent nonsense --id " + id);
    EXPECT_EQ(bad.exit_code, 2);
    EXPECT_NE(bad.err.find("nonsense"), std::string::npos) << bad.err;
  }

  // Query by mesh file, with a label filter and k.
  const testing::GeneratedFile& f = files->back();
  CommandResult by_mesh =
      RunTpr(cluster_, "--json query -k 5 --label " + f.label + " " + set +
                           "/" + f.relative_path);
  ASSERT_EQ(by_mesh.exit_code, 0) << by_mesh.err;
  std::vector<std::string> lines = Lines(by_mesh.out);
  ASSERT_EQ(lines.size(), 2u) << by_mesh.out;  // two poses carry that label
  int rank;
  std::string id, label;
  double distance;
  ASSERT_TRUE(ParseNeighbor(lines[0], &rank, &id, &label, &distance));
  EXPECT_EQ(id, f.relative_path);
  EXPECT_EQ(distance, 0.0);

  // Human output of the other subcommands, and their failures.
  CommandResult human = RunTpr(cluster_, "query -k 2 --id " + f.relative_path);
  EXPECT_EQ(human.exit_code, 0);
  EXPECT_NE(human.out.find("rank"), std::string::npos);
  EXPECT_EQ(RunTpr(cluster_, "get " + f.relative_path).exit_code, 0);
  EXPECT_EQ(Lines(RunTpr(cluster_, "--json list").out).size(), 6u);
  EXPECT_EQ(JsonInt(RunTpr(cluster_, "--json stats").out, "models"), 6);
  EXPECT_EQ(RunTpr(cluster_, "remove " + f.relative_path).exit_code, 0);
  EXPECT_EQ(RunTpr(cluster_, "get " + f.relative_path).exit_code, 1);
  EXPECT_EQ(RunTpr(cluster_, "remove " + f.relative_path).exit_code, 1);
  EXPECT_EQ(RunTpr(cluster_, "query --id no/such/id").exit_code, 1);
  EXPECT_EQ(RunTpr(cluster_, "query -k 0 --id " + files->front().relative_path)
                .exit_code,
            2);  // a usage error
  CommandResult extract =
      RunTpr(cluster_, "extract " + set + "/" + files->front().relative_path);
  EXPECT_EQ(extract.exit_code, 0) << extract.err;
  EXPECT_NE(extract.out.find("points"), std::string::npos);
  EXPECT_EQ(RunTpr(cluster_, "extract " + set + "/broken/bad.off").exit_code,
            1);
}

// Writes a closed torus (major radius 2, minor 0.6; 24 x 12 quads split in
// two triangles) as OFF: genus 1, one handle.
void WriteTorusOff(const std::string& path) {
  constexpr int kMajor = 24, kMinor = 12;
  std::ofstream out(path);
  out << "OFF\n" << kMajor * kMinor << " " << 2 * kMajor * kMinor << " 0\n";
  for (int i = 0; i < kMajor; ++i) {
    const double u = 2 * M_PI * i / kMajor;
    for (int j = 0; j < kMinor; ++j) {
      const double v = 2 * M_PI * j / kMinor;
      out << (2 + 0.6 * std::cos(v)) * std::cos(u) << " "
          << (2 + 0.6 * std::cos(v)) * std::sin(u) << " " << 0.6 * std::sin(v)
          << "\n";
    }
  }
  auto at = [](int i, int j) { return (i % kMajor) * kMinor + (j % kMinor); };
  for (int i = 0; i < kMajor; ++i) {
    for (int j = 0; j < kMinor; ++j) {
      out << "3 " << at(i, j) << " " << at(i + 1, j) << " " << at(i + 1, j + 1)
          << "\n3 " << at(i, j) << " " << at(i + 1, j + 1) << " "
          << at(i, j + 1) << "\n";
    }
  }
}

// `--handles` reaches the extractor (ExtractOptions.handles) from `tpr
// extract` and `tpr add`, and the stored signature records the treatment:
// the default cuts a torus's handle (a warning says so), `keep` describes it
// as it is (the paper's method), and another word is refused by the parser.
TEST_F(CliTest, HandlesOptionSelectsCutOrKeep) {
  const std::string torus = cluster_.dir() + "/torus.off";
  WriteTorusOff(torus);
  CommandResult cut = RunTpr(cluster_, "--json extract " + torus);
  ASSERT_EQ(cut.exit_code, 0) << cut.err;
  EXPECT_NE(cut.out.find("\"handles\":\"HANDLE_TREATMENT_CUT\""),
            std::string::npos)
      << cut.out;
  EXPECT_NE(cut.out.find("cut 1 handle(s)"), std::string::npos) << cut.out;
  EXPECT_EQ(JsonInt(cut.out, "genus"), 1);  // the input's genus

  CommandResult keep =
      RunTpr(cluster_, "--json extract --handles KEEP " + torus);
  ASSERT_EQ(keep.exit_code, 0) << keep.err;
  EXPECT_NE(keep.out.find("\"handles\":\"HANDLE_TREATMENT_KEEP\""),
            std::string::npos)
      << keep.out;
  EXPECT_EQ(keep.out.find("cut 1 handle(s)"), std::string::npos) << keep.out;

  CommandResult bad = RunTpr(cluster_, "extract --handles sew " + torus);
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.err.find("sew"), std::string::npos) << bad.err;

  ASSERT_EQ(RunTpr(cluster_, "add --handles keep " + torus).exit_code, 0);
  CommandResult stored = RunTpr(cluster_, "--json get " + FileId(torus));
  ASSERT_EQ(stored.exit_code, 0) << stored.err;
  EXPECT_NE(stored.out.find("HANDLE_TREATMENT_KEEP"), std::string::npos)
      << stored.out;
  ASSERT_EQ(RunTpr(cluster_, "add --update " + torus).exit_code, 0);
  stored = RunTpr(cluster_, "--json get " + FileId(torus));
  EXPECT_NE(stored.out.find("HANDLE_TREATMENT_CUT"), std::string::npos)
      << stored.out;
}

// Media through the command: `tpr add` stores a thumbnail (with the
// overlay) and a preview per model, `tpr get ID --thumbnail --preview`
// saves them, byte for byte what the extractor returns for the same file
// (`tpr extract --thumbnail --preview`, and the extractor called directly);
// `--no-media` stores none, and then `tpr get --thumbnail` fails naming
// `tpr add --update`, which makes them.
TEST_F(CliTest, AddStoresMediaAndGetSavesThem) {
  const std::string set = cluster_.dir() + "/set";
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(set, 2, 1, 1500);
  ASSERT_TRUE(files.ok()) << files.status();
  // A file argument's id is its path as given.
  const std::string id_a = set + "/" + (*files)[0].relative_path;
  const std::string id_b = set + "/" + (*files)[1].relative_path;
  ASSERT_EQ(RunTpr(cluster_, "add " + id_a).exit_code, 0);
  ASSERT_EQ(RunTpr(cluster_, "add --no-media " + id_b).exit_code, 0);

  const std::string png = cluster_.dir() + "/a.png";
  const std::string ply = cluster_.dir() + "/a.ply";
  CommandResult got = RunTpr(cluster_, "get " + FileId(id_a) + " --thumbnail " +
                                           png + " --preview " + ply);
  ASSERT_EQ(got.exit_code, 0) << got.err;
  EXPECT_NE(got.out.find("thumbnail and preview stored"), std::string::npos)
      << got.out;
  // The oracle: the extractor asked for the same pictures of the same file.
  absl::StatusOr<client::ExtractorClient> extractor =
      client::ExtractorClient::Connect(cluster_.extractor(0).address());
  ASSERT_TRUE(extractor.ok());
  v1::MediaOptions media;
  media.set_thumbnail(true);
  media.set_thumbnail_overlay(true);
  media.set_preview(true);
  absl::StatusOr<v1::ExtractResponse> direct =
      extractor->ExtractFile(id_a, {}, media);
  ASSERT_TRUE(direct.ok()) << direct.status();
  ASSERT_FALSE(direct->media().thumbnail_png().empty());
  EXPECT_EQ(ReadBytes(png), direct->media().thumbnail_png());
  EXPECT_EQ(ReadBytes(ply), direct->media().preview_ply());
  // tpr extract writes the same files without the indexer.
  const std::string png2 = cluster_.dir() + "/a2.png";
  const std::string ply2 = cluster_.dir() + "/a2.ply";
  CommandResult extracted =
      RunTpr(cluster_,
             "extract " + id_a + " --thumbnail " + png2 + " --preview " + ply2);
  ASSERT_EQ(extracted.exit_code, 0) << extracted.err;
  EXPECT_EQ(ReadBytes(png2), direct->media().thumbnail_png());
  EXPECT_EQ(ReadBytes(ply2), direct->media().preview_ply());
  // The preview reads back through intake.
  absl::StatusOr<extract::LoadedMesh> back =
      extract::LoadMeshFromFile(ply, extract::IntakeOptions{});
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_LE(back->mesh.triangles.size(), 5000u);

  // Without media: a clear refusal, then --update makes them.
  CommandResult none =
      RunTpr(cluster_, "get " + FileId(id_b) + " --thumbnail " + png);
  EXPECT_EQ(none.exit_code, 1);
  EXPECT_NE(none.err.find("NOT_FOUND"), std::string::npos) << none.err;
  EXPECT_NE(none.err.find("tpr add --update"), std::string::npos) << none.err;
  ASSERT_EQ(RunTpr(cluster_, "add --update " + id_b).exit_code, 0);
  EXPECT_EQ(
      RunTpr(cluster_, "get " + FileId(id_b) + " --thumbnail " + png).exit_code,
      0);
  // Usage: media flags take one id.
  EXPECT_EQ(RunTpr(cluster_, "get " + id_a + " " + id_b + " --preview " + ply)
                .exit_code,
            2);
}

// `--topology` reaches the extractor (ExtractOptions.topology) from `tpr
// extract` and `tpr add`, and the signature records the method: persistence
// by default, `paper` when asked, another word refused by the parser.
TEST_F(CliTest, TopologyOptionSelectsPersistenceOrPaper) {
  const std::string torus = cluster_.dir() + "/torus_topology.off";
  WriteTorusOff(torus);
  CommandResult plain = RunTpr(cluster_, "--json extract " + torus);
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  EXPECT_NE(plain.out.find("\"topology\":\"TOPOLOGY_METHOD_PERSISTENCE\""),
            std::string::npos)
      << plain.out;
  CommandResult paper =
      RunTpr(cluster_, "--json extract --topology PAPER " + torus);
  ASSERT_EQ(paper.exit_code, 0) << paper.err;
  EXPECT_NE(paper.out.find("\"topology\":\"TOPOLOGY_METHOD_PAPER\""),
            std::string::npos)
      << paper.out;
  CommandResult bad = RunTpr(cluster_, "extract --topology morse " + torus);
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.err.find("morse"), std::string::npos) << bad.err;
  ASSERT_EQ(RunTpr(cluster_, "add --topology paper " + torus).exit_code, 0);
  CommandResult stored = RunTpr(cluster_, "--json get " + FileId(torus));
  ASSERT_EQ(stored.exit_code, 0) << stored.err;
  EXPECT_NE(stored.out.find("TOPOLOGY_METHOD_PAPER"), std::string::npos)
      << stored.out;
}

// Labels from --manifest; then SIGTERM while a search stream is open: the
// server stops accepting calls
// but the open stream still delivers every neighbour, then the process
// exits 0.
TEST_F(CliTest, ManifestLabelsThenSigtermDuringASearchStreamEndsCleanly) {
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(cluster_.dir() + "/set", 2, 2, 800);
  ASSERT_TRUE(files.ok());
  // Labels from a manifest override the folder names.
  std::string manifest;
  for (const testing::GeneratedFile& f : *files) {
    absl::StrAppend(&manifest, f.relative_path, " manifest_", f.label, "\n");
  }
  testing::WriteFile(cluster_.dir() + "/MANIFEST.txt", manifest);
  CommandResult add =
      RunTpr(cluster_, "add " + cluster_.dir() + "/set --manifest " +
                           cluster_.dir() + "/MANIFEST.txt");
  ASSERT_EQ(add.exit_code, 0) << add.out << add.err;
  absl::StatusOr<client::IndexerClient> indexer =
      client::IndexerClient::Connect(cluster_.indexer().address());
  ASSERT_TRUE(indexer.ok());
  for (const testing::GeneratedFile& f : *files) {
    absl::StatusOr<v1::Model> m = indexer->Get(f.relative_path);
    ASSERT_TRUE(m.ok()) << m.status();
    EXPECT_EQ(m->label(), "manifest_" + f.label);
  }
  v1::SearchRequest request;
  request.set_id(files->front().relative_path);
  request.set_k(4);
  std::unique_ptr<client::SearchStream> stream = indexer->Search(request);
  v1::Neighbor n;
  ASSERT_TRUE(stream->Next(&n));
  int exit_code = -2;
  std::thread stopper([&] { exit_code = cluster_.indexer().Stop(SIGTERM); });
  int more = 0;
  while (stream->Next(&n)) ++more;
  const absl::Status finished = stream->Finish();
  stopper.join();
  // Either the stream completed (graceful) or the server cancelled it at the
  // end of its grace period; both are clean ends, and the process exits 0.
  EXPECT_TRUE(finished.ok() || absl::IsCancelled(finished) ||
              absl::IsUnavailable(finished))
      << finished;
  if (finished.ok()) {
    EXPECT_EQ(more, 3);
  }
  EXPECT_EQ(exit_code, 0);
}

// `tpr inspect --local` runs without services: the PLY it writes has the
// input's vertices, every point vertex red and every ring vertex black, as
// the library's explanation of the same mesh says.
TEST(CliInspectTest, WritesTheRegionsPointsAndRingsOfTheLocalExtraction) {
  testing::TempDir dir;
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(dir.path() + "/set", 1, 1, 2000);
  ASSERT_TRUE(files.ok());
  const std::string mesh = dir.path() + "/set/" + files->front().relative_path;
  const std::string out = dir.path() + "/out.ply";
  const std::string command =
      absl::StrCat(testing::BinaryPath("tpr"), " inspect --local --ascii ",
                   mesh, " -o ", out, " > /dev/null");
  ASSERT_EQ(std::system(command.c_str()), 0);

  absl::StatusOr<extract::LoadedMesh> loaded =
      extract::LoadMeshFromFile(mesh, {});
  ASSERT_TRUE(loaded.ok());
  extract::Options options;
  options.explain = true;
  absl::StatusOr<extract::ExtractResult> r =
      extract::ExtractSignature(loaded->mesh, loaded->stats, options);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_TRUE(r->explanation.has_value());

  // Parse the ASCII PLY: header, then "x y z r g b" per vertex.
  std::ifstream in(out);
  std::string line;
  int64_t vertices = -1;
  while (std::getline(in, line) && line != "end_header") {
    if (line.rfind("element vertex ", 0) == 0)
      vertices = std::stoll(line.substr(15));
  }
  ASSERT_EQ(vertices, loaded->stats.vertices);
  std::vector<std::array<int, 3>> colours;
  for (int64_t v = 0; v < vertices && std::getline(in, line); ++v) {
    std::stringstream fields(line);
    double x, y, z;
    std::array<int, 3> c;
    fields >> x >> y >> z >> c[0] >> c[1] >> c[2];
    colours.push_back(c);
  }
  ASSERT_EQ(static_cast<int64_t>(colours.size()), vertices);
  const std::array<int, 3> kRed = {220, 20, 20}, kBlack = {20, 20, 20};
  int points = 0, rings = 0;
  for (size_t f = 0; f < r->signature.features.size(); ++f) {
    const bool is_point =
        r->signature.features[f].kind == extract::FeatureKind::kPoint;
    (is_point ? points : rings)++;
    for (int32_t v : r->explanation->feature_vertices[f]) {
      if (is_point) {
        // Rings are drawn after points, so a point on a ring shows black.
        EXPECT_TRUE(colours[v] == kRed || colours[v] == kBlack)
            << "point vertex " << v;
      } else {
        EXPECT_EQ(colours[v], kBlack) << "ring vertex " << v;
      }
    }
  }
  EXPECT_GT(points, 0);
  // Unmarked vertices carry a region colour: neither red nor black.
  const int64_t marked =
      std::count_if(colours.begin(), colours.end(),
                    [&](const auto& c) { return c == kRed || c == kBlack; });
  EXPECT_LT(marked, vertices);
}

// `tpr inspect` without --local extracts through tpr-extractor
// (ExtractOptions.explain): the file equals the --local one byte for byte.
// Without a reachable extractor it fails with exit code 1.
TEST_F(CliTest, InspectThroughTheServiceEqualsTheLocalExtraction) {
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(cluster_.dir() + "/set", 1, 1, 2000);
  ASSERT_TRUE(files.ok());
  const std::string mesh =
      cluster_.dir() + "/set/" + files->front().relative_path;
  const std::string remote = cluster_.dir() + "/remote.ply",
                    local = cluster_.dir() + "/local.ply";
  CommandResult r =
      RunTpr(cluster_, "--json inspect " + mesh + " -o " + remote);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("\"local\":false"), std::string::npos) << r.out;
  ASSERT_EQ(
      RunTpr(cluster_, "inspect --local " + mesh + " -o " + local).exit_code,
      0);
  auto read = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream bytes;
    bytes << in.rdbuf();
    return bytes.str();
  };
  const std::string remote_bytes = read(remote);
  EXPECT_GT(remote_bytes.size(), 1000u);
  EXPECT_TRUE(remote_bytes == read(local))
      << "service and local inspect differ";
  CommandResult down =
      RunTpr(cluster_, "--extractor 127.0.0.1:1 --timeout 2 inspect " + mesh +
                           " -o " + remote + ".2");
  EXPECT_EQ(down.exit_code, 1);
  EXPECT_NE(down.err.find("UNAVAILABLE"), std::string::npos) << down.err;
}

// Ids and labels holding control characters stay on one line in the text
// output of `tpr list` and `tpr query` (escaped as \n, \t, \xHH), and are
// exact in --json output.
TEST_F(CliTest, ControlCharactersInIdsAreEscapedInTextOutput) {
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(cluster_.dir() + "/set", 1, 1, 800);
  ASSERT_TRUE(files.ok());
  absl::StatusOr<client::ExtractorClient> extractor =
      client::ExtractorClient::Connect(cluster_.extractor_addresses());
  absl::StatusOr<client::IndexerClient> indexer =
      client::IndexerClient::Connect(cluster_.indexer().address());
  ASSERT_TRUE(extractor.ok() && indexer.ok());
  absl::StatusOr<v1::ExtractResponse> r = extractor->ExtractFile(
      cluster_.dir() + "/set/" + files->front().relative_path);
  ASSERT_TRUE(r.ok()) << r.status();
  v1::Model model;
  model.set_id("two\nlines\x01");
  model.set_label("tab\tbed");
  *model.mutable_signature() = r->signature();
  absl::StatusOr<bool> created = indexer->Upsert(model, true);
  if (!created.ok()) {
    // An indexer that defines an id alphabet may refuse such an id; then
    // it must say so clearly, and nothing is left to escape.
    ASSERT_TRUE(absl::IsInvalidArgument(created.status())) << created.status();
    GTEST_SKIP() << "the indexer refuses control characters in ids";
  }
  CommandResult list = RunTpr(cluster_, "list");
  ASSERT_EQ(list.exit_code, 0) << list.err;
  EXPECT_EQ(Lines(list.out).size(), 1u) << list.out;
  EXPECT_NE(list.out.find("two\\nlines\\x01"), std::string::npos) << list.out;
  EXPECT_NE(list.out.find("tab\\tbed"), std::string::npos) << list.out;
  CommandResult query = RunTpr(cluster_, "query -k 1 --id 'two\nlines\x01'");
  ASSERT_EQ(query.exit_code, 0) << query.err;
  EXPECT_EQ(Lines(query.out).size(), 2u) << query.out;  // header and one row
  CommandResult json = RunTpr(cluster_, "--json list");
  EXPECT_NE(json.out.find("\"id\":\"two\\nlines\\u0001\""), std::string::npos)
      << json.out;
}

}  // namespace
}  // namespace tpr::cli
