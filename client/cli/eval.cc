#include "client/cli/eval.h"

#include <stdlib.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <set>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/command.h"
#include "eval/lib/d2.h"
#include "eval/lib/dataset.h"
#include "eval/lib/distance_matrix.h"
#include "eval/lib/metrics.h"
#include "eval/lib/plots.h"
#include "eval/lib/report.h"
#include "extractor/lib/mesh_io.h"

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
    const tpr::v1::Ranking* ranking, tpr::v1::Intent intent,
    const tpr::client::CallOptions& call) {
  const std::string& id = items[evaluated[query]].id;
  tpr::v1::SearchRequest request;
  request.set_id(id);
  request.set_exclude_self(true);
  request.set_k(k);
  request.set_intent(intent);
  if (ranking != nullptr) *request.mutable_ranking() = *ranking;
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

// RankAll runs SearchOne for every evaluated model (`jobs` at a time) under
// `ranking` (null: `intent`). Failed queries are added to
// `failures` with `what` in front; the model stays in the others' rankings.
std::vector<eval::Query> RankAll(
    const IndexerClient& indexer, const std::vector<Item>& items,
    const std::vector<int>& evaluated,
    const std::unordered_map<std::string, int>& index_of, int k,
    const tpr::v1::Ranking* ranking, tpr::v1::Intent intent, int jobs,
    const tpr::client::CallOptions& call, const std::string& what,
    Failures* failures) {
  std::vector<absl::StatusOr<eval::Query>> results(evaluated.size());
  Progress progress(evaluated.size(), absl::StrFormat("%-10s", what));
  ParallelFor(evaluated.size(), jobs, [&](size_t e) {
    results[e] = SearchOne(indexer, items, evaluated, index_of,
                           static_cast<int>(e), k, ranking, intent, call);
    progress.Step(items[evaluated[e]].id,
                  results[e].ok() ? "queried" : "FAILED");
  });
  std::vector<eval::Query> queries;
  for (size_t e = 0; e < evaluated.size(); ++e) {
    if (results[e].ok()) {
      queries.push_back(std::move(*results[e]));
    } else {
      failures->emplace_back(
          items[evaluated[e]].id,
          absl::StrCat(what, ": ", results[e].status().ToString()));
    }
  }
  return queries;
}

// D2Queries ranks the evaluated models by the D2 shape distribution
// (Osada et al. 2001; eval/lib/d2.h, the options tpr-eval-local uses),
// computed here from the mesh files, not by the services: the baseline of
// the side-by-side tables. A file that cannot be read fails the
// column (NOT_FOUND / INVALID_ARGUMENT naming it).
absl::StatusOr<std::vector<eval::Query>> D2Queries(
    const std::vector<Item>& items, const std::vector<int>& evaluated,
    int jobs) {
  std::vector<std::vector<double>> histograms(evaluated.size());
  std::vector<absl::Status> errors(evaluated.size());
  Progress progress(evaluated.size(), "D2        ");
  ParallelFor(evaluated.size(), jobs, [&](size_t e) {
    const Item& item = items[evaluated[e]];
    absl::StatusOr<extract::LoadedMesh> loaded =
        extract::LoadMeshFromFile(item.path, extract::IntakeOptions{});
    if (loaded.ok()) {
      histograms[e] = eval::D2Histogram(loaded->mesh, eval::D2Options{});
    } else {
      errors[e] = loaded.status();
    }
    progress.Step(item.id, loaded.ok() ? "D2" : "FAILED");
  });
  for (size_t e = 0; e < evaluated.size(); ++e) {
    if (!errors[e].ok()) {
      return absl::Status(
          errors[e].code(),
          absl::StrCat(items[evaluated[e]].id, ": ", errors[e].message()));
    }
  }
  return eval::LeaveOneOutQueries(
      eval::PairwiseDistances(evaluated.size(), jobs, [&] {
        return [&](size_t i, size_t j) {
          return eval::D2Distance(histograms[i], histograms[j]);
        };
      }));
}

// One column of `tpr eval --compare`: a way of ranking and its scores, or
// why it could not be computed.
struct Column {
  std::string key;    // JSON key
  std::string title;  // text heading
  std::vector<eval::Query> queries;
  eval::Scores scores;      // of `queries`, once the labels are known
  std::string unavailable;  // "" when scored
};

// CompareTableText prints the columns side by side: overall NN, FT, ST, E,
// DCG and mAP per column, then NN and FT per class and column.
std::string CompareTableText(const std::vector<Column>& columns,
                             const eval::ClassSizes& sizes) {
  std::string out =
      absl::StrFormat("%-34s %6s %6s %6s %6s %6s %6s\n", "side by side", "NN",
                      "FT", "ST", "E", "DCG", "mAP");
  for (const Column& c : columns) {
    if (!c.unavailable.empty()) {
      absl::StrAppendFormat(&out, "%-34s unavailable: %s\n", c.title,
                            c.unavailable);
      continue;
    }
    const eval::Metrics& m = c.scores.overall;
    absl::StrAppendFormat(&out, "%-34s %6.3f %6.3f %6.3f %6.3f %6.3f %6.3f\n",
                          c.title, m.nn, m.ft, m.st, m.e, m.dcg, m.map);
  }
  out += "\nper class, NN / FT:\n";
  absl::StrAppendFormat(&out, "%-16s", "class");
  for (const Column& c : columns) absl::StrAppendFormat(&out, " %13s", c.key);
  out += "\n";
  for (const auto& [label, count] : sizes) {
    absl::StrAppendFormat(&out, "%-16s", TextField(label));
    for (const Column& c : columns) {
      auto it = c.scores.per_class.find(label);
      if (!c.unavailable.empty() || it == c.scores.per_class.end()) {
        absl::StrAppendFormat(&out, " %13s", "-");
      } else {
        absl::StrAppendFormat(&out, "   %.3f/%.3f", it->second.nn,
                              it->second.ft);
      }
    }
    out += "\n";
  }
  return out;
}

// CompareJson returns {"<key>":{<metrics>,"per_class":{...}} or
// {"unavailable":"why"},...}.
std::string CompareJson(const std::vector<Column>& columns,
                        const eval::ClassSizes& sizes) {
  std::string out = "{";
  for (const Column& c : columns) {
    if (out.size() > 1) out += ",";
    absl::StrAppend(&out, JsonString(c.key),
                    ":{\"title\":", JsonString(c.title), ",");
    if (!c.unavailable.empty()) {
      absl::StrAppend(&out, "\"unavailable\":", JsonString(c.unavailable), "}");
    } else {
      absl::StrAppend(&out, eval::MetricsJsonFields(c.scores.overall),
                      ",\"per_class\":", eval::PerClassJson(c.scores, sizes),
                      "}");
    }
  }
  return out + "}";
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
  if (!extractor) return 2;
  std::optional<IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 2;
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
  std::vector<Column> compare;  // with options.compare: the other columns
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
    const auto start = std::chrono::steady_clock::now();
    queries = RankAll(*indexer, *items, evaluated, index_of,
                      static_cast<int>(k), nullptr, options.intent,
                      options.add.jobs, call, "query", &failures);
    query_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start)
            .count();
    if (options.compare) {
      // The side-by-side columns: the other two intents, the paper's
      // distance and the spectrum alone, ranked by the indexer
      // (SearchRequest.intent and .ranking), D2 here.
      const tpr::v1::Ranking paper = *NamedRanking("paper");
      const tpr::v1::Ranking spectrum = *NamedRanking("spectrum");
      std::vector<std::tuple<std::string, std::string, const tpr::v1::Ranking*,
                             tpr::v1::Intent>>
          columns;
      for (tpr::v1::Intent intent :
           {tpr::v1::INTENT_BALANCED, tpr::v1::INTENT_IDENTITY,
            tpr::v1::INTENT_KIND}) {
        if (IntentTitle(intent) == std::string(IntentTitle(options.intent))) {
          continue;  // the default column
        }
        columns.emplace_back(IntentTitle(intent),
                             absl::StrCat("intent ", IntentTitle(intent)),
                             nullptr, intent);
      }
      columns.emplace_back("paper", "paper TPR (the EMD of the paper alone)",
                           &paper, tpr::v1::INTENT_UNSPECIFIED);
      columns.emplace_back("spectrum", "spectrum alone (ShapeDNA)", &spectrum,
                           tpr::v1::INTENT_UNSPECIFIED);
      for (const auto& [key, title, ranking, intent] : columns) {
        Failures column_failures;
        Column c;
        c.key = key;
        c.title = title;
        c.queries = RankAll(*indexer, *items, evaluated, index_of,
                            static_cast<int>(k), ranking, intent,
                            options.add.jobs, call, key, &column_failures);
        if (c.queries.empty() && !column_failures.empty()) {
          c.unavailable = column_failures.front().second;
        } else {
          failures.insert(failures.end(), column_failures.begin(),
                          column_failures.end());
        }
        compare.push_back(std::move(c));
      }
      absl::StatusOr<std::vector<eval::Query>> d2 =
          D2Queries(*items, evaluated, options.add.jobs);
      Column c;
      c.key = "d2";
      c.title = "D2 (Osada et al. 2001, L1; local)";
      if (d2.ok()) {
        c.queries = std::move(*d2);
      } else {
        c.unavailable = d2.status().ToString();
      }
      compare.push_back(std::move(c));
    }
  }
  std::sort(failures.begin(), failures.end());

  std::vector<std::string> labels;
  for (int i : evaluated) labels.push_back((*items)[i].label);
  const eval::ClassSizes models_per_class = eval::CountClasses(labels);
  const eval::Scores scores = eval::Evaluate(labels, queries);
  // The measure of class separation under the served distance.
  const eval::ClassSeparation separation = eval::Separation(labels, queries);
  const bool evaluable = scores.overall.queries > 0;
  if (options.compare) {
    for (Column& c : compare) {
      if (c.unavailable.empty()) c.scores = eval::Evaluate(labels, c.queries);
    }
    Column own;
    own.key = "default";
    own.title =
        absl::StrCat("default (intent ", IntentTitle(options.intent), ")");
    own.scores = scores;
    compare.insert(compare.begin(), std::move(own));
  }

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
        "\"within_between\":%s,%s"
        "\"extract_seconds\":%.3f,\"query_seconds\":%.3f,\"out\":%s}\n",
        evaluated.size(), models_per_class.size(),
        eval::MetricsJsonFields(scores.overall).c_str(),
        eval::PerClassJson(scores, models_per_class).c_str(), items->size(),
        added, updated, skipped, failures.size(),
        FailuresJson(failures).c_str(),
        eval::JsonNumber(separation.Ratio()).c_str(),
        options.compare
            ? absl::StrCat(
                  "\"compare\":", CompareJson(compare, models_per_class), ",")
                  .c_str()
            : "",
        add_seconds, query_seconds,
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
      if (options.compare) {
        std::printf("\n%s",
                    CompareTableText(compare, models_per_class).c_str());
      }
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
       sub.add_flag("--compare", flags->options.compare,
                    "also rank by the other two intents, the paper's "
                    "distance alone and the spectrum alone (each one more "
                    "leave-one-out pass through the indexer's tree) and by "
                    "D2 (computed here from the files), and print them side "
                    "by side, overall and per class");
       AddIntentOption(sub, &flags->options.intent);
       sub.add_flag("--update", flags->options.add.update,
                    "re-extract ids already in the indexer (default: use them "
                    "as they are)");
       AddHandlesOption(sub, &flags->options.add.extract);
       AddTopologyOption(sub, &flags->options.add.extract);
       return [flags](const Globals& g) {
         return RunEval(g, flags->dataset, flags->options);
       };
     },
     "tpr eval shapes/ --out results/"});

}  // namespace

}  // namespace tpr::cli
