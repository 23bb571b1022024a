#include "client/cli/add.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>
#include <utility>

#include "absl/strings/str_cat.h"
#include "client/cli/command.h"

namespace tpr::cli {

namespace fs = std::filesystem;
using tpr::client::ExtractorClient;
using tpr::client::IndexerClient;

absl::StatusOr<std::vector<AddOutcome>> AddItems(
    const ExtractorClient& extractor, const IndexerClient& indexer,
    const std::vector<Item>& items, const AddOptions& options,
    const tpr::client::CallOptions& call, Progress* progress) {
  // Safe re-runs: one listing tells which ids exist, instead of a Get each.
  std::set<std::string> present;
  if (!options.update) {
    absl::StatusOr<std::vector<tpr::v1::Model>> existing =
        indexer.ListAll("", &call);
    if (!existing.ok()) return existing.status();
    for (const tpr::v1::Model& m : *existing) present.insert(m.id());
  }
  std::vector<AddOutcome> outcomes(items.size());
  ParallelFor(items.size(), options.jobs, [&](size_t i) {
    const Item& item = items[i];
    AddOutcome& out = outcomes[i];
    if (present.count(item.id)) {
      out.kind = AddOutcome::kSkipped;
      if (progress != nullptr) progress->Step(item.id, "skipped");
      return;
    }
    absl::Status status;
    bool created = false;
    absl::StatusOr<tpr::v1::ExtractResponse> r =
        extractor.ExtractFile(item.path, options.extract, options.media, &call);
    if (r.ok()) {
      tpr::v1::Model model;
      model.set_id(item.id);
      model.set_label(item.label);
      (*model.mutable_metadata())["file_name"] =
          fs::path(item.path).filename().string();
      *model.mutable_signature() = std::move(*r->mutable_signature());
      if (r->has_media())
        *model.mutable_media() = std::move(*r->mutable_media());
      absl::StatusOr<bool> c = indexer.Upsert(model, options.update, &call);
      status = c.status();
      created = c.ok() && *c;
    } else {
      status = r.status();
    }
    if (absl::IsAlreadyExists(status)) {  // added meanwhile by someone else
      out.kind = AddOutcome::kSkipped;
    } else if (!status.ok()) {
      out.kind = AddOutcome::kFailed;
      out.error = status.ToString();
    } else {
      out.kind = created ? AddOutcome::kAdded : AddOutcome::kUpdated;
    }
    if (progress != nullptr) {
      static const char* const kNames[] = {"added", "updated", "skipped",
                                           "FAILED"};
      progress->Step(item.id, kNames[out.kind]);
    }
  });
  return outcomes;
}

namespace {

struct AddFlags {
  std::vector<std::string> paths;
  std::string manifest;
  AddOptions options;
  bool no_media = false;
  bool no_overlay = false;
};

int RunAdd(const Globals& g, const AddFlags& flags) {
  AddOptions options = flags.options;
  options.media.set_thumbnail(!flags.no_media);
  options.media.set_thumbnail_overlay(!flags.no_media && !flags.no_overlay);
  options.media.set_preview(!flags.no_media);
  absl::StatusOr<std::vector<Item>> items = eval::CollectItems(flags.paths);
  if (!items.ok()) return Fail("add", items.status());
  if (!flags.manifest.empty()) {
    absl::StatusOr<std::map<std::string, std::string>> labels =
        eval::ReadManifest(flags.manifest);
    if (!labels.ok()) return Fail("--manifest", labels.status());
    for (Item& item : *items) {
      auto it = labels->find(item.id);
      if (it != labels->end()) item.label = it->second;
    }
  }
  std::optional<ExtractorClient> extractor = ConnectExtractor(g);
  if (!extractor) return 1;
  std::optional<IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 1;
  const tpr::client::CallOptions call = CallOptionsFor(g);

  Progress progress(items->size());
  absl::StatusOr<std::vector<AddOutcome>> outcomes =
      AddItems(*extractor, *indexer, *items, options, call, &progress);
  if (!outcomes.ok()) return Fail("listing the index", outcomes.status());

  int added = 0, updated = 0, skipped = 0;
  Failures failures;
  for (size_t i = 0; i < items->size(); ++i) {
    const AddOutcome& o = (*outcomes)[i];
    switch (o.kind) {
      case AddOutcome::kAdded:
        ++added;
        break;
      case AddOutcome::kUpdated:
        ++updated;
        break;
      case AddOutcome::kSkipped:
        ++skipped;
        break;
      case AddOutcome::kFailed:
        failures.emplace_back((*items)[i].id, o.error);
        break;
    }
  }
  std::sort(failures.begin(), failures.end());
  if (g.json) {
    std::printf(
        "{\"files\":%zu,\"added\":%d,\"updated\":%d,\"skipped\":%d,\"failed\":%"
        "zu,"
        "\"seconds\":%.3f,\"failures\":%s}\n",
        items->size(), added, updated, skipped, failures.size(),
        progress.Elapsed(), FailuresJson(failures).c_str());
  } else {
    std::printf(
        "%zu files: %d added, %d updated, %d skipped (already present), %zu "
        "failed "
        "in %.1f s\n",
        items->size(), added, updated, skipped, failures.size(),
        progress.Elapsed());
    PrintFailures(failures);
  }
  return failures.empty() ? 0 : 1;
}

const bool kRegistered = RegisterCommand(
    {"add",
     "index mesh files or folders (recursive); ids are paths relative to the "
     "folder given (a file argument: its path as given), labels the parent "
     "folder names (or --manifest)",
     [](CLI::App& sub) {
       auto flags = std::make_shared<AddFlags>();
       sub.add_option("PATH", flags->paths, "mesh files or folders")
           ->required();
       sub.add_option("--manifest", flags->manifest,
                      "file of 'RELATIVE/PATH LABEL' lines");
       sub.add_option("--jobs,-j", flags->options.jobs, "parallel uploads")
           ->capture_default_str()
           ->check(CLI::Range(1, 64));
       sub.add_flag("--update", flags->options.update,
                    "replace ids already present (default: skip them); also "
                    "makes the thumbnails and previews of models stored "
                    "without them");
       sub.add_flag("--no-media", flags->no_media,
                    "store no thumbnail or preview (default: both, made by "
                    "the extractor)");
       sub.add_flag("--no-overlay", flags->no_overlay,
                    "thumbnails without the TPR overlay (default: points as "
                    "red dots, rings as dark lines)");
       AddHandlesOption(sub, &flags->options.extract);
       AddTopologyOption(sub, &flags->options.extract);
       return [flags](const Globals& g) { return RunAdd(g, *flags); };
     }});

}  // namespace

}  // namespace tpr::cli
