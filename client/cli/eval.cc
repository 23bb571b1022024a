#include "client/cli/eval.h"

#include <stdlib.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <unordered_map>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/command.h"
#include "eval/lib/dataset.h"
#include "eval/lib/distance_matrix.h"
#include "eval/lib/metrics.h"
#include "eval/lib/plots.h"
#include "eval/lib/report.h"

namespace tpr::cli {
namespace {

namespace fs = std::filesystem;
using tpr::client::ExtractorClient;
using tpr::client::IndexerClient;

// The folder the pictures go to: `requested`, or a new temporary one.
absl::StatusOr<std::string> OutputFolder(const std::string& requested) {
  if (!requested.empty()) {
    std::error_code ec;
    fs::create_directories(requested, ec);
    if (ec) {
      return absl::PermissionDeniedError(
          absl::StrCat("cannot create ", requested, ": ", ec.message()));
    }
    return requested;
  }
  const char* tmp = std::getenv("TMPDIR");
  std::string pattern =
      absl::StrCat(tmp != nullptr && *tmp ? tmp : "/tmp", "/tpr-eval-XXXXXX");
  if (mkdtemp(pattern.data()) == nullptr) {
    return absl::PermissionDeniedError(
        absl::StrCat("cannot create a temporary folder ", pattern));
  }
  return pattern;
}

// One leave-one-out search: `query` (index into `ids`) against the index,
// by id, without itself, k = every model. Neighbours that are not part of
// the evaluated set (other models the indexer holds) are dropped; Evaluate
// counts evaluated models absent from a ranking as retrieved last.
absl::StatusOr<eval::Query> SearchOne(
    const IndexerClient& indexer, const std::vector<Item>& items,
    const std::vector<int>& evaluated,
    const std::unordered_map<std::string, int>& index_of, int query, int k,
    const tpr::client::CallOptions& call) {
  const std::string& id = items[evaluated[query]].id;
  tpr::v1::SearchRequest request;
  request.set_id(id);
  request.set_exclude_self(true);
  request.set_k(k);
  std::unique_ptr<tpr::client::SearchStream> stream =
      indexer.Search(request, &call);
  eval::Query q;
  q.model = query;
  std::vector<bool> seen(evaluated.size(), false);
  for (tpr::v1::Neighbor n; stream->Next(&n);) {
    auto it = index_of.find(n.id());
    if (it == index_of.end() || it->second == query || seen[it->second])
      continue;
    seen[it->second] = true;
    q.ranking.push_back({it->second, n.distance()});
  }
  absl::Status status = stream->Finish();
  if (!status.ok()) return status;
  return q;
}

}  // namespace

int RunEval(const Globals& g, const std::string& dataset,
            const EvalOptions& options) {
  absl::StatusOr<std::vector<Item>> items = eval::ReadDataset(dataset);
  if (!items.ok()) {
    Fail("eval", items.status());
    return 2;
  }
  std::optional<ExtractorClient> extractor = ConnectExtractor(g);
  if (!extractor) return 1;
  std::optional<IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 1;
  const tpr::client::CallOptions call = CallOptionsFor(g);

  // 1. Extract and index, exactly as `tpr add` (same skip/--update rules).
  Progress add_progress(items->size(), "extracting");
  absl::StatusOr<std::vector<AddOutcome>> outcomes =
      AddItems(*extractor, *indexer, *items, options.add, call, &add_progress);
  if (!outcomes.ok()) return Fail("listing the index", outcomes.status());
  const double add_seconds = add_progress.Elapsed();

  Failures failures;
  std::vector<int> evaluated;  // indices into *items
  int added = 0, updated = 0, skipped = 0;
  for (size_t i = 0; i < items->size(); ++i) {
    const AddOutcome& o = (*outcomes)[i];
    if (o.kind == AddOutcome::kFailed) {
      failures.emplace_back((*items)[i].id, o.error);
      continue;
    }
    (o.kind == AddOutcome::kAdded     ? added
     : o.kind == AddOutcome::kUpdated ? updated
                                      : skipped)++;
    evaluated.push_back(static_cast<int>(i));
  }

  // 2. Leave-one-out queries. k covers the whole index, so that every
  // evaluated model is ranked even when the indexer holds other models too.
  std::vector<eval::Query> queries;
  double query_seconds = 0;
  if (evaluated.size() >= 2) {
    absl::StatusOr<tpr::v1::StatsResponse> stats = indexer->Stats(&call);
    if (!stats.ok()) return Fail("indexer stats", stats.status());
    const int64_t k = std::max<int64_t>(stats->models(),
                                        static_cast<int64_t>(evaluated.size()));
    if (k > std::numeric_limits<int32_t>::max()) {
      return Fail("eval", absl::ResourceExhaustedError(
                              "the index is too large to rank fully"));
    }
    std::unordered_map<std::string, int> index_of;
    for (size_t e = 0; e < evaluated.size(); ++e) {
      index_of[(*items)[evaluated[e]].id] = static_cast<int>(e);
    }
    std::vector<absl::StatusOr<eval::Query>> results(evaluated.size());
    Progress query_progress(evaluated.size(), "querying  ");
    ParallelFor(evaluated.size(), options.add.jobs, [&](size_t e) {
      results[e] = SearchOne(*indexer, *items, evaluated, index_of,
                             static_cast<int>(e), static_cast<int>(k), call);
      query_progress.Step((*items)[evaluated[e]].id,
                          results[e].ok() ? "queried" : "FAILED");
    });
    query_seconds = query_progress.Elapsed();
    for (size_t e = 0; e < evaluated.size(); ++e) {
      if (results[e].ok()) {
        queries.push_back(std::move(*results[e]));
      } else {
        // The model stays in the others' rankings; only its own query is
        // left out.
        failures.emplace_back(
            (*items)[evaluated[e]].id,
            absl::StrCat("query: ", results[e].status().ToString()));
      }
    }
  }
  std::sort(failures.begin(), failures.end());

  std::vector<std::string> labels;
  for (int i : evaluated) labels.push_back((*items)[i].label);
  const eval::ClassSizes models_per_class = eval::CountClasses(labels);
  const eval::Scores scores = eval::Evaluate(labels, queries);
  // Issue 9's measure of class separation under the served distance.
  const eval::ClassSeparation separation = eval::Separation(labels, queries);
  const bool evaluable = scores.overall.queries > 0;

  // 3. Pictures.
  std::string written;
  absl::Status pictures = absl::OkStatus();
  std::string out_dir;
  if (evaluable) {
    absl::StatusOr<std::string> folder = OutputFolder(options.out_dir);
    if (!folder.ok()) {
      pictures = folder.status();
    } else {
      out_dir = *folder;
      const fs::path out(out_dir);
      const std::string name =
          fs::path(dataset).lexically_normal().filename().string();
      pictures =
          eval::WriteTextFile((out / "precision_recall.svg").string(),
                              eval::PrecisionRecallSvg(
                                  {{"TPR, all classes", scores.overall.pr}},
                                  absl::StrCat("Precision-recall, ", name, " (",
                                               evaluated.size(), " models)")));
      if (pictures.ok()) {
        pictures = eval::WriteTextFile(
            (out / "similarity.svg").string(),
            eval::SimilaritySvg(eval::MeanSimilarity(labels, queries),
                                absl::StrCat("Mean class similarity, ", name)));
      }
      written = (out / "precision_recall.svg").string() + ", " +
                (out / "similarity.svg").string();
    }
  }

  // 4. Report.
  if (g.json) {
    std::printf(
        "{\"models\":%zu,\"classes\":%zu,%s,\"per_class\":%s,\"files\":%zu,"
        "\"added\":%d,\"updated\":%d,\"skipped\":%d,\"failed\":%zu,"
        "\"failures\":%s,"
        "\"within_between\":%s,"
        "\"extract_seconds\":%.3f,\"query_seconds\":%.3f,\"out\":%s}\n",
        evaluated.size(), models_per_class.size(),
        eval::MetricsJsonFields(scores.overall).c_str(),
        eval::PerClassJson(scores, models_per_class).c_str(), items->size(),
        added, updated, skipped, failures.size(),
        FailuresJson(failures).c_str(),
        eval::JsonNumber(separation.Ratio()).c_str(), add_seconds,
        query_seconds,
        evaluable && pictures.ok() ? JsonString(out_dir).c_str() : "null");
  } else {
    std::printf(
        "%zu models in %zu classes (%d added, %d updated, %d already indexed, "
        "%zu "
        "failed); extraction and indexing %.1f s, queries %.1f s\n\n",
        evaluated.size(), models_per_class.size(), added, updated, skipped,
        failures.size(), add_seconds, query_seconds);
    if (evaluable) {
      std::fputs(eval::ScoresTable(scores, models_per_class).c_str(), stdout);
      std::printf(
          "mean distance within classes %.4g, between %.4g, ratio %.4f (the "
          "indexer's distance)\n",
          separation.within, separation.between, separation.Ratio());
    }
    PrintFailures(failures);
    if (evaluable && pictures.ok())
      std::printf("\nwrote %s\n", written.c_str());
  }
  if (!evaluable) {
    std::fprintf(
        stderr,
        "tpr eval: nothing could be evaluated (%zu of %zu models usable; "
        "metrics need a class with at least two)\n",
        evaluated.size(), items->size());
    return 1;
  }
  if (!pictures.ok()) return Fail("eval pictures", pictures);
  return 0;
}

namespace {

struct EvalFlags {
  std::string dataset;
  EvalOptions options;
};

const bool kRegistered = RegisterCommand(
    {"eval",
     "retrieval quality of a labelled set through the services: extract and "
     "index every model (as add), query each by id against all others, print "
     "NN, FT, ST, E, DCG and mAP per class and overall, and draw the "
     "precision-recall curve and the mean class-similarity matrix (SVG)",
     [](CLI::App& sub) {
       auto flags = std::make_shared<EvalFlags>();
       sub.add_option("DATASET", flags->dataset,
                      "folder of class subfolders, or manifest file of 'PATH "
                      "CLASS' lines (paths relative to it)")
           ->required();
       sub.add_option("--out,-o", flags->options.out_dir,
                      "folder for precision_recall.svg and similarity.svg "
                      "(default: a new temporary folder, e.g. "
                      "/tmp/tpr-eval-XXXXXX, named in the output)");
       sub.add_option("--jobs,-j", flags->options.add.jobs,
                      "parallel uploads and queries")
           ->capture_default_str()
           ->check(CLI::Range(1, 64));
       sub.add_flag("--update", flags->options.add.update,
                    "re-extract ids already in the indexer (default: use them "
                    "as they are)");
       return [flags](const Globals& g) {
         return RunEval(g, flags->dataset, flags->options);
       };
     }});

}  // namespace

}  // namespace tpr::cli
