// `tpr eval` end to end: a labelled set written by the tpr-synth binary, both
// service binaries on loopback, `tpr --json eval` on the folder and on a
// manifest. The reported metrics must equal an independent in-process
// computation (extraction by the library, EMD between every pair, the
// rankings scored by tpr::eval::Evaluate) to 1e-9: the services must
// produce the same signatures and distances as the libraries. Also: the
// pictures are well-formed SVG, a bad mesh is listed and left out, and a set
// with nothing to evaluate exits non-zero.
#include <gtest/gtest.h>
#include <stdio.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "eval/lib/d2.h"
#include "eval/lib/metrics.h"
#include "eval/lib/tpr_descriptor.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/metric.h"
#include "tests/service/extsvc_test_util.h"

namespace tpr::cli {
namespace {

namespace fs = std::filesystem;

using ::tpr::testing::CommandResult;
using ::tpr::testing::RunTpr;

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// The JSON value of `key` in the object that starts at `from` (the first
// occurrence after it), as a number; NaN when absent or not a number.
double JsonNumber(const std::string& json, size_t from,
                  const std::string& key) {
  const std::string needle = "\"" + key + "\":";
  const size_t at = json.find(needle, from);
  if (at == std::string::npos) return std::nan("");
  const char* start = json.c_str() + at + needle.size();
  char* end = nullptr;
  const double x = std::strtod(start, &end);
  return end == start ? std::nan("") : x;
}

// The 21 numbers of "pr":[...] after `from`.
std::vector<double> JsonPr(const std::string& json, size_t from) {
  std::vector<double> pr;
  const size_t at = json.find("\"pr\":[", from);
  if (at == std::string::npos) return pr;
  const size_t close = json.find(']', at);
  std::stringstream list(json.substr(at + 6, close - at - 6));
  for (std::string item; std::getline(list, item, ',');)
    pr.push_back(std::stod(item));
  return pr;
}

// A labelled mesh of the evaluation set.
struct LabelledMesh {
  std::string path;
  std::string label;
};

// The manifest tpr-synth writes: "<relative path> <class>" per line.
std::vector<LabelledMesh> ReadSynthManifest(const std::string& dir) {
  std::vector<LabelledMesh> meshes;
  std::ifstream in(dir + "/MANIFEST.txt");
  std::string rel, label;
  while (in >> rel >> label) meshes.push_back({dir + "/" + rel, label});
  return meshes;
}

// The oracle's distances: the same meshes extracted in-process with the
// library's defaults (as the extractor service runs it), prepared with the
// default ground distance (as the indexer does), EMD between every pair.
using Matrix = std::vector<std::vector<double>>;

// Besides the index's distance (tpr): the paper's EMD alone, the spectral
// term at weight 1 alone, and D2 from the same loaded meshes, the columns
// of `tpr eval --compare`.
struct Matrices {
  Matrix tpr, paper, spectrum, d2;
};

absl::StatusOr<Matrices> InProcessMatrices(
    const std::vector<LabelledMesh>& meshes) {
  std::vector<index::PreparedSignature> prepared;
  std::vector<std::vector<double>> d2;
  for (const LabelledMesh& m : meshes) {
    absl::StatusOr<extract::LoadedMesh> loaded =
        extract::LoadMeshFromFile(m.path, {});
    if (!loaded.ok()) return loaded.status();
    d2.push_back(eval::D2Histogram(loaded->mesh, eval::D2Options{}));
    absl::StatusOr<extract::ExtractResult> r = extract::ExtractSignature(
        loaded->mesh, loaded->stats, extract::Options{});
    if (!r.ok()) return r.status();
    absl::StatusOr<index::PreparedSignature> p = index::Prepare(
        eval::ToIndexSignature(r->signature), index::GroundDistanceOptions{});
    if (!p.ok()) return p.status();
    prepared.push_back(std::move(*p));
  }
  const size_t n = prepared.size();
  const Matrix zero(n, std::vector<double>(n, 0.0));
  Matrices d{zero, zero, zero, zero};
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = i + 1; j < n; ++j) {
      d.tpr[i][j] = d.tpr[j][i] =
          index::Distance(prepared[i], prepared[j],
                          index::IntentWeights(index::Intent::kBalanced));
      d.paper[i][j] = d.paper[j][i] = index::Emd(prepared[i], prepared[j]);
      d.spectrum[i][j] = d.spectrum[j][i] =
          index::SpectralDistance(prepared[i], prepared[j]);
      d.d2[i][j] = d.d2[j][i] = eval::D2Distance(d2[i], d2[j]);
    }
  }
  return d;
}

absl::StatusOr<Matrix> InProcessDistances(
    const std::vector<LabelledMesh>& meshes) {
  absl::StatusOr<Matrices> d = InProcessMatrices(meshes);
  if (!d.ok()) return d.status();
  return d->tpr;
}

// The oracle's scores: each model ranked against all the others by `d`,
// scored by Evaluate under `labels`.
struct Oracle {
  eval::Scores scores;
  std::vector<std::string> labels;
  double within_between = 0.0;  // mean within-class / mean between-class d
};

Oracle Score(const Matrix& d, const std::vector<std::string>& labels) {
  std::vector<eval::Query> queries;
  for (size_t i = 0; i < d.size(); ++i) {
    eval::Query q{static_cast<int>(i), {}};
    for (size_t j = 0; j < d.size(); ++j) {
      if (j != i) q.ranking.push_back({static_cast<int>(j), d[i][j]});
    }
    queries.push_back(std::move(q));
  }
  double within = 0.0, between = 0.0;
  int nw = 0, nb = 0;
  for (size_t i = 0; i < d.size(); ++i) {
    for (size_t j = i + 1; j < d.size(); ++j) {
      (labels[i] == labels[j] ? within : between) += d[i][j];
      ++(labels[i] == labels[j] ? nw : nb);
    }
  }
  return {eval::Evaluate(labels, queries), labels,
          (within / nw) / (between / nb)};
}

// Checks that the metrics object of `json` starting at `from` equals `m`.
void ExpectMetrics(const std::string& json, size_t from, const eval::Metrics& m,
                   const std::string& what) {
  constexpr double kTol = 1e-9;
  EXPECT_NEAR(JsonNumber(json, from, "nn"), m.nn, kTol) << what;
  EXPECT_NEAR(JsonNumber(json, from, "ft"), m.ft, kTol) << what;
  EXPECT_NEAR(JsonNumber(json, from, "st"), m.st, kTol) << what;
  EXPECT_NEAR(JsonNumber(json, from, "e"), m.e, kTol) << what;
  EXPECT_NEAR(JsonNumber(json, from, "dcg"), m.dcg, kTol) << what;
  EXPECT_NEAR(JsonNumber(json, from, "map"), m.map, kTol) << what;
  EXPECT_EQ(JsonNumber(json, from, "queries"), m.queries) << what;
  const std::vector<double> pr = JsonPr(json, from);
  ASSERT_EQ(pr.size(), static_cast<size_t>(eval::kRecallLevels)) << what;
  for (int r = 0; r < eval::kRecallLevels; ++r)
    EXPECT_NEAR(pr[r], m.pr[r], kTol) << what;
}

// Checks the whole report against the oracle: counts, overall metrics and
// every class's.
void ExpectReport(const std::string& json, const Oracle& oracle) {
  EXPECT_EQ(JsonNumber(json, 0, "models"),
            static_cast<double>(oracle.labels.size()))
      << json;
  EXPECT_EQ(JsonNumber(json, 0, "classes"),
            static_cast<double>(oracle.scores.per_class.size()))
      << json;
  // Overall fields come before "per_class".
  ASSERT_LT(json.find("\"nn\":"), json.find("\"per_class\"")) << json;
  ExpectMetrics(json, 0, oracle.scores.overall, "overall");
  EXPECT_NEAR(JsonNumber(json, 0, "within_between"), oracle.within_between,
              1e-9)
      << json;
  ASSERT_EQ(oracle.scores.per_class.size(), 3u);
  for (const auto& [cls, m] : oracle.scores.per_class) {
    const size_t at = json.find("\"" + cls + "\":{");
    ASSERT_NE(at, std::string::npos) << cls << " in " << json;
    EXPECT_EQ(JsonNumber(json, at, "models"),
              std::count(oracle.labels.begin(), oracle.labels.end(), cls))
        << cls;
    ExpectMetrics(json, at, m, cls);
  }
}

void ExpectSvg(const std::string& path) {
  ASSERT_TRUE(fs::is_regular_file(path)) << path;
  std::string svg = ReadText(path);
  while (!svg.empty() && std::isspace(static_cast<unsigned char>(svg.back())))
    svg.pop_back();
  EXPECT_EQ(svg.rfind("<svg", 0), 0u) << path << ": " << svg.substr(0, 80);
  ASSERT_GE(svg.size(), 6u);
  EXPECT_EQ(svg.substr(svg.size() - 6), "</svg>") << path;
}

// MixedManifest returns the manifest text ("<path relative to `dir`>
// <label>" lines) that labels the last pose ("_2") of each synthetic class
// as the next class, and those labels in `labels`. The synthetic classes
// separate perfectly; mixed, retrieval is imperfect and every metric a
// non-trivial function of the exact ranking.
std::string MixedManifest(const std::vector<LabelledMesh>& meshes,
                          const std::string& dir,
                          std::vector<std::string>* labels) {
  std::map<std::string, int> class_index;
  for (const LabelledMesh& m : meshes)
    class_index.emplace(m.label, class_index.size());
  std::string manifest;
  for (const LabelledMesh& m : meshes) {
    const std::string stem = fs::path(m.path).stem().string();
    const bool last_pose = stem.substr(stem.rfind('_') + 1) == "2";
    labels->push_back(
        absl::StrCat("mix_", (class_index[m.label] + last_pose) % 3));
    absl::StrAppend(&manifest,
                    fs::path(m.path).lexically_relative(dir).string(), " ",
                    labels->back(), "\n");
  }
  return manifest;
}

class EvalCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(cluster_.Start().ok());
    set_ = cluster_.dir() + "/set";
    const std::string synth =
        absl::StrCat(testing::BinaryPath("tpr-synth"), " --out ", set_,
                     " --classes 3 --poses 3 --vertices 1500 --seed 7",
                     " --jobs 2 > /dev/null 2>&1");
    ASSERT_EQ(std::system(synth.c_str()), 0) << synth;
    meshes_ = ReadSynthManifest(set_);
    ASSERT_EQ(meshes_.size(), 9u);
  }
  testing::Cluster cluster_;
  std::string set_;
  std::vector<LabelledMesh> meshes_;
};

TEST_F(EvalCliTest, FolderAndManifestReportTheInProcessMetrics) {
  absl::StatusOr<Matrix> d = InProcessDistances(meshes_);
  ASSERT_TRUE(d.ok()) << d.status();
  std::vector<std::string> labels;
  for (const LabelledMesh& m : meshes_) labels.push_back(m.label);
  const Oracle by_class = Score(*d, labels);
  const Oracle* oracle = &by_class;

  // A bad mesh inside a class folder: listed with its reason, left out.
  const std::string first_class = oracle->labels.front();
  testing::WriteFile(set_ + "/" + first_class + "/bad.off",
                     "OFF\n3 1 0\n0 0 0\n1 0 0\n");

  // Folder of class subfolders.
  const std::string out = cluster_.dir() + "/out";
  CommandResult folder =
      RunTpr(cluster_, "--json eval --jobs 3 --out " + out + " " + set_);
  ASSERT_EQ(folder.exit_code, 0) << folder.out << folder.err;
  SCOPED_TRACE(folder.out);
  ExpectReport(folder.out, *oracle);
  EXPECT_EQ(JsonNumber(folder.out, 0, "failed"), 1);
  EXPECT_NE(folder.out.find(first_class + "/bad.off"), std::string::npos);
  EXPECT_NE(folder.out.find("INVALID_ARGUMENT"), std::string::npos);
  ExpectSvg(out + "/precision_recall.svg");
  ExpectSvg(out + "/similarity.svg");
  // Every class name appears in the similarity matrix.
  const std::string similarity = ReadText(out + "/similarity.svg");
  for (const auto& [cls, m] : oracle->scores.per_class) {
    EXPECT_NE(similarity.find(cls), std::string::npos) << cls;
  }

  // A manifest one folder up, with its own labels: ids are its paths
  // ("set/<class>/..."), new to the indexer, which still holds the folder
  // run's models; those must not enter the rankings. The synthetic classes
  // separate perfectly, so this manifest mixes them: the last pose of each
  // class is labelled as the next class. Retrieval is then imperfect and
  // every metric a non-trivial function of the exact ranking.
  std::vector<std::string> mixed_labels;
  const std::string manifest =
      MixedManifest(meshes_, cluster_.dir(), &mixed_labels);
  const Oracle mixed = Score(*d, mixed_labels);
  EXPECT_LT(mixed.scores.overall.ft, 0.9);  // the check below is not trivial
  EXPECT_GT(mixed.scores.overall.ft, 0.0);
  testing::WriteFile(cluster_.dir() + "/MANIFEST.txt", manifest);
  const std::string out2 = cluster_.dir() + "/out2";
  CommandResult listed = RunTpr(cluster_, "--json eval --out " + out2 + " " +
                                              cluster_.dir() + "/MANIFEST.txt");
  ASSERT_EQ(listed.exit_code, 0) << listed.out << listed.err;
  ExpectReport(listed.out, mixed);
  EXPECT_EQ(JsonNumber(listed.out, 0, "added"), 9);
  EXPECT_EQ(JsonNumber(listed.out, 0, "failed"), 0);
  ExpectSvg(out2 + "/precision_recall.svg");
  ExpectSvg(out2 + "/similarity.svg");

  // Re-running the folder skips what is indexed and reports the same; the
  // human table names every class and the overall row.
  CommandResult again = RunTpr(cluster_, "eval --out " + out + " " + set_);
  EXPECT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.out.find("9 already indexed"), std::string::npos)
      << again.out;
  for (const auto& [cls, m] : oracle->scores.per_class) {
    EXPECT_NE(again.out.find(cls), std::string::npos) << again.out;
  }
  EXPECT_NE(again.out.find("ALL"), std::string::npos) << again.out;
}

TEST_F(EvalCliTest, CompareShowsPaperSpectrumAndD2BesideTheDefault) {
  // `tpr eval --compare`: the paper's distance and the spectrum alone as
  // the indexer ranks them (SearchRequest.ranking), and D2 computed by the
  // client, each scored as the in-process oracle scores its own matrix.
  // The classes are mixed as in the manifest test above (the last pose of
  // each class labelled as the next class), so that no metric is 1.
  absl::StatusOr<Matrices> d = InProcessMatrices(meshes_);
  ASSERT_TRUE(d.ok()) << d.status();
  std::vector<std::string> labels;
  const std::string manifest = MixedManifest(meshes_, cluster_.dir(), &labels);
  testing::WriteFile(cluster_.dir() + "/MANIFEST.txt", manifest);
  CommandResult r =
      RunTpr(cluster_, "--json eval --compare --out " + cluster_.dir() + "/o " +
                           cluster_.dir() + "/MANIFEST.txt");
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  SCOPED_TRACE(r.out);
  const size_t compare = r.out.find("\"compare\":{");
  ASSERT_NE(compare, std::string::npos);
  const std::pair<const char*, const Matrix*> columns[] = {
      {"default", &d->tpr},
      {"paper", &d->paper},
      {"spectrum", &d->spectrum},
      {"d2", &d->d2}};
  for (const auto& [key, matrix] : columns) {
    const Oracle oracle = Score(*matrix, labels);
    const size_t at = r.out.find(absl::StrCat("\"", key, "\":{"), compare);
    ASSERT_NE(at, std::string::npos) << key;
    ExpectMetrics(r.out, at, oracle.scores.overall, key);
    const std::string cls = oracle.scores.per_class.begin()->first;
    const size_t class_at = r.out.find("\"" + cls + "\":{", at);
    ASSERT_NE(class_at, std::string::npos) << key << " " << cls;
    ExpectMetrics(r.out, class_at, oracle.scores.per_class.begin()->second,
                  absl::StrCat(key, " ", cls));
  }
  // The four columns rank differently here, so the check above tells them
  // apart: the paper's and the spectrum's rankings are not the default's.
  EXPECT_NE(Score(d->paper, labels).scores.overall.map,
            Score(d->spectrum, labels).scores.overall.map);

  // The text report prints them side by side, per class too.
  CommandResult text =
      RunTpr(cluster_, "eval --compare --out " + cluster_.dir() + "/o " +
                           cluster_.dir() + "/MANIFEST.txt");
  ASSERT_EQ(text.exit_code, 0) << text.err;
  for (const char* want : {"side by side", "paper TPR", "spectrum alone", "D2",
                           "per class, NN / FT", "mix_0"}) {
    EXPECT_NE(text.out.find(want), std::string::npos) << want << text.out;
  }
}

// Without --out, the pictures go to a new temporary folder (under $TMPDIR)
// named in the report, never into the working directory.
TEST_F(EvalCliTest, DefaultOutputIsATemporaryFolderNotTheWorkingTree) {
  const std::string cwd = cluster_.dir() + "/cwd",
                    tmp = cluster_.dir() + "/tmp";
  fs::create_directories(cwd);
  fs::create_directories(tmp);
  const std::string command = absl::StrCat(
      "cd ", cwd, " && TMPDIR=", tmp,
      " TPR_EXTRACTOR=", cluster_.extractor_addresses(),
      " TPR_INDEXER=", cluster_.indexer().address(), " ",
      testing::BinaryPath("tpr"), " --json eval ", set_, " 2>/dev/null");
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string out;
  char buffer[4096];
  for (size_t n; (n = fread(buffer, 1, sizeof(buffer), pipe)) > 0;)
    out.append(buffer, n);
  ASSERT_EQ(pclose(pipe), 0) << out;
  EXPECT_TRUE(fs::is_empty(cwd)) << "the working directory was written to";
  const std::string key = "\"out\":\"";
  const size_t at = out.find(key);
  ASSERT_NE(at, std::string::npos) << out;
  const std::string folder = out.substr(
      at + key.size(), out.find('"', at + key.size()) - at - key.size());
  EXPECT_EQ(folder.rfind(tmp + "/tpr-eval-", 0), 0u) << folder;
  ExpectSvg(folder + "/precision_recall.svg");
  ExpectSvg(folder + "/similarity.svg");
}

TEST_F(EvalCliTest, NothingToEvaluateExitsNonZero) {
  // Only bad meshes: listed, and the exit code says nothing was evaluated.
  const std::string bad = cluster_.dir() + "/bad";
  testing::WriteFile(bad + "/a/one.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n");
  testing::WriteFile(bad + "/a/two.off", "not a mesh\n");
  CommandResult r =
      RunTpr(cluster_, "--json eval --out " + cluster_.dir() + "/o " + bad);
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_EQ(JsonNumber(r.out, 0, "failed"), 2) << r.out;
  EXPECT_NE(r.err.find("nothing could be evaluated"), std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(cluster_.dir() + "/o/precision_recall.svg"));

  // One good model per class: no query has anything relevant to find.
  const std::string single = cluster_.dir() + "/single";
  fs::create_directories(single + "/x");
  fs::copy_file(meshes_[0].path, single + "/x/m.off");
  EXPECT_EQ(RunTpr(cluster_, "eval --out " + cluster_.dir() + "/o " + single)
                .exit_code,
            1);

  // Bad arguments: a missing dataset, a manifest naming a missing file, a
  // mesh outside any class folder.
  EXPECT_EQ(
      RunTpr(cluster_, "eval " + cluster_.dir() + "/no/such/set").exit_code, 2);
  testing::WriteFile(cluster_.dir() + "/M.txt", "missing.off a\n");
  CommandResult missing = RunTpr(cluster_, "eval " + cluster_.dir() + "/M.txt");
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find("missing.off"), std::string::npos) << missing.err;
  fs::copy_file(meshes_[0].path, set_ + "/loose.off");
  CommandResult loose = RunTpr(cluster_, "eval " + set_);
  EXPECT_EQ(loose.exit_code, 2);
  EXPECT_NE(loose.err.find("loose.off"), std::string::npos) << loose.err;
}

}  // namespace
}  // namespace tpr::cli
