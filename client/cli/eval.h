// `tpr eval`: retrieval quality of a labelled set measured through the
// services, as the paper's section 7 and the shape-retrieval benchmarks
// (PSB, SHREC) do. Every model is extracted and indexed (as `tpr add`),
// then queried by id against all the others (leave-one-out); the rankings
// give NN, FT, ST, E, DCG, mAP and the precision-recall curve
// (eval/lib/metrics.h), per class and overall, and the pictures of
// eval/lib/plots.h (precision-recall; mean class similarity, paper Fig. 11),
// printed by eval/lib/report.h.
//
//   tpr eval shapes/ --out results/     # or a MANIFEST.txt
//   // prints the table (or one JSON object), writes results/*.svg
#ifndef TPR_CLIENT_CLI_EVAL_H_
#define TPR_CLIENT_CLI_EVAL_H_

#include <string>

#include "client/cli/add.h"
#include "client/cli/cli_util.h"
#include "client/cli/connection.h"

namespace tpr::cli {

// EvalOptions: how `tpr eval` runs.
struct EvalOptions {
  // Extraction/upload and query parallelism, and whether ids already in the
  // indexer are re-extracted (update) or used as they are (default), exactly
  // as `tpr add`. Defaults: 4 jobs, no update.
  AddOptions add;
  // Folder the pictures are written to (created). Default "": a new
  // temporary folder (mkdtemp under $TMPDIR, else /tmp), named in the
  // output, so that a run never litters the working tree.
  std::string out_dir;
  // Also score, side by side with the run's intent: the other two intents
  // (SearchRequest.intent), the paper's distance alone and the spectrum
  // alone (SearchRequest.ranking; every one searched with the indexer's
  // tree) and D2 (eval/lib/d2.h, computed by the client from the files).
  // Default false.
  bool compare = false;
  // What the queries search for (SearchRequest.intent; --intent). Default
  // INTENT_UNSPECIFIED: balanced.
  tpr::v1::Intent intent = tpr::v1::INTENT_UNSPECIFIED;
};

// RunEval evaluates `dataset` (a folder of class subfolders, or a manifest
// file of "<path> <class>" lines, paths relative to it; see
// eval::ReadDataset) through the extractor and indexer of `g`: models that
// fail (unreadable or bad meshes, refused upserts, failed queries) are
// listed with their reasons and left out of the metrics. Prints a table per
// class and overall (models, NN, FT, ST, E, DCG, mAP), or with g.json one
// object {"models", "classes", "nn", "ft", "st", "e", "dcg", "map", "pr",
// "per_class": {class: {...}}, "failures": [...], ...; with
// options.compare also "compare": {"default"|<the two other intents>|
// "paper"|"spectrum"|"d2":
// {"title", metrics, "per_class"} or {"title", "unavailable": why}}}, and
// writes
// OUT/precision_recall.svg and OUT/similarity.svg (OUT: options.out_dir,
// or a fresh temporary folder).
// Returns the exit code: 0 when metrics were computed (even if some models
// failed), 1 when nothing could be evaluated (no class with two models
// left), the services could not be reached, or the pictures could not be
// written; 2 for a bad dataset argument.
// Cost: one extraction per model (unless skipped), N searches with k = the
// index size, i.e. about N^2 EMDs on the indexer.
int RunEval(const Globals& g, const std::string& dataset,
            const EvalOptions& options);

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_EVAL_H_
