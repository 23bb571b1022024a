#include "client/cli/add.h"

#include <openssl/evp.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <utility>

#include "absl/strings/str_cat.h"
#include "client/cli/collect.h"
#include "client/cli/command.h"

namespace tpr::cli {

namespace fs = std::filesystem;
using tpr::client::ExtractorClient;
using tpr::client::IndexerClient;

namespace {

// Calls failing with these codes would fail for every later item too.
bool StopsEverything(const absl::Status& status) {
  return absl::IsUnavailable(status) || absl::IsUnimplemented(status) ||
         absl::IsUnauthenticated(status) || absl::IsPermissionDenied(status);
}

// The hex SHA-256 of the bytes of `path`. NOT_FOUND when it cannot be read.
absl::StatusOr<std::string> Sha256File(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot read ", path));
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr);
  std::vector<char> buffer(1 << 16);
  while (in.read(buffer.data(), buffer.size()) || in.gcount() > 0) {
    EVP_DigestUpdate(ctx, buffer.data(), static_cast<size_t>(in.gcount()));
  }
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int size = 0;
  EVP_DigestFinal_ex(ctx, digest, &size);
  EVP_MD_CTX_free(ctx);
  std::string hex;
  for (unsigned int i = 0; i < size; ++i)
    absl::StrAppend(&hex, absl::Hex(digest[i], absl::kZeroPad2));
  return hex;
}

// Marks the items AddItems need not send: ids present (unless update) and
// contents indexed under another id or met earlier (unless
// allow_duplicates). `hashes[i]` empty: the file could not be read.
void MarkSkipped(const std::vector<Item>& items,
                 const std::vector<std::string>& hashes,
                 const std::vector<tpr::v1::Model>& existing,
                 const AddOptions& options, std::vector<AddOutcome>* out,
                 std::vector<bool>* send) {
  std::set<std::string> present;
  std::map<std::string, std::string> id_of_hash;
  for (const tpr::v1::Model& m : existing) {
    present.insert(m.id());
    auto h = m.metadata().find("sha256");
    if (h != m.metadata().end()) id_of_hash.emplace(h->second, m.id());
  }
  for (size_t i = 0; i < items.size(); ++i) {
    (*send)[i] = false;
    AddOutcome& o = (*out)[i];
    o.kind = AddOutcome::kSkipped;
    if (!options.update && present.count(items[i].id)) {
      o.reason = "already present";
      continue;
    }
    if (!options.allow_duplicates && !hashes[i].empty()) {
      auto [it, fresh] = id_of_hash.emplace(hashes[i], items[i].id);
      if (!fresh && it->second != items[i].id) {
        o.reason = absl::StrCat("same content as ", it->second,
                                " (--allow-duplicates adds it anyway)");
        continue;
      }
    }
    (*send)[i] = true;
  }
}

}  // namespace

absl::StatusOr<std::vector<AddOutcome>> AddItems(
    const ExtractorClient& extractor, const IndexerClient& indexer,
    const std::vector<Item>& items, const AddOptions& options,
    const tpr::client::CallOptions& call, Progress* progress) {
  // Safe re-runs: one listing tells which ids and contents exist.
  absl::StatusOr<std::vector<tpr::v1::Model>> existing =
      indexer.ListAll("", &call);
  if (!existing.ok()) return existing.status();
  std::vector<std::string> hashes(items.size());
  for (size_t i = 0; i < items.size(); ++i) {
    absl::StatusOr<std::string> h = Sha256File(items[i].path);
    if (h.ok()) hashes[i] = *std::move(h);
  }
  std::vector<AddOutcome> outcomes(items.size());
  std::vector<bool> send(items.size());
  MarkSkipped(items, hashes, *existing, options, &outcomes, &send);

  std::atomic<bool> stop{false};
  std::atomic<size_t> done{0};
  std::mutex mu;
  absl::Status fatal;
  ParallelFor(items.size(), options.jobs, [&](size_t i) {
    const Item& item = items[i];
    AddOutcome& out = outcomes[i];
    if (!send[i] || stop.load()) {
      if (progress != nullptr && !stop.load())
        progress->Step(item.id, "skipped");
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
      if (!hashes[i].empty()) (*model.mutable_metadata())["sha256"] = hashes[i];
      *model.mutable_signature() = std::move(*r->mutable_signature());
      if (r->has_media())
        *model.mutable_media() = std::move(*r->mutable_media());
      absl::StatusOr<bool> c = indexer.Upsert(model, options.update, &call);
      status = c.status();
      created = c.ok() && *c;
    } else {
      status = r.status();
    }
    if (StopsEverything(status)) {
      std::lock_guard<std::mutex> lock(mu);
      if (!stop.exchange(true)) fatal = status;
      return;
    }
    if (absl::IsAlreadyExists(status)) {  // added meanwhile by someone else
      out.kind = AddOutcome::kSkipped;
      out.reason = "already present";
    } else if (!status.ok()) {
      out.kind = AddOutcome::kFailed;
      out.error = status.ToString();
    } else {
      out.kind = created ? AddOutcome::kAdded : AddOutcome::kUpdated;
    }
    ++done;
    if (progress != nullptr) {
      static const char* const kNames[] = {"added", "updated", "skipped",
                                           "FAILED"};
      progress->Step(item.id, kNames[out.kind]);
    }
  });
  if (stop.load()) {
    return absl::Status(
        fatal.code(),
        absl::StrCat(fatal.message(), " (stopped after ", done.load(), " of ",
                     items.size(), " files; those are kept)"));
  }
  return outcomes;
}

namespace {

struct AddFlags {
  std::vector<std::string> paths;
  std::string manifest;
  Naming naming;
  bool allow_duplicates = false;
  AddOptions options;
  bool no_media = false;
  bool no_overlay = false;
};

// The files of `flags` as items, with --manifest's labels; prints the
// reason and returns the exit code when there are none to add.
std::optional<int> CollectItems(const AddFlags& flags, std::vector<Item>* items,
                                std::vector<SkippedFile>* skipped) {
  absl::StatusOr<Collected> collected =
      CollectAddFiles(flags.paths, flags.naming);
  if (!collected.ok()) {
    const int code = Fail("add", collected.status());
    return absl::IsInvalidArgument(collected.status()) ? 2 : code;
  }
  std::map<std::string, std::string> labels;
  if (!flags.manifest.empty()) {
    absl::StatusOr<std::map<std::string, std::string>> read =
        eval::ReadManifest(flags.manifest);
    if (!read.ok()) return Fail("--manifest", read.status());
    labels = *std::move(read);
  }
  for (const AddFile& f : collected->files) {
    Item item{f.path, f.id, f.label};
    auto it = labels.find(f.relative);
    if (it != labels.end() && flags.naming.label.empty())
      item.label = it->second;
    items->push_back(std::move(item));
  }
  *skipped = std::move(collected->skipped);
  return std::nullopt;
}

void PrintAddReport(const Globals& g, const std::vector<Item>& items,
                    const std::vector<AddOutcome>& outcomes,
                    std::vector<SkippedFile> skipped, double seconds,
                    Failures* failures) {
  int added = 0, updated = 0, present = 0;
  for (size_t i = 0; i < items.size(); ++i) {
    const AddOutcome& o = outcomes[i];
    if (o.kind == AddOutcome::kAdded) ++added;
    if (o.kind == AddOutcome::kUpdated) ++updated;
    if (o.kind == AddOutcome::kFailed)
      failures->emplace_back(items[i].id, o.error);
    if (o.kind == AddOutcome::kSkipped && o.reason == "already present")
      ++present;
    else if (o.kind == AddOutcome::kSkipped)
      skipped.push_back({items[i].path, o.reason});
  }
  std::sort(failures->begin(), failures->end());
  if (g.json) {
    std::string list = "[";
    for (const SkippedFile& f : skipped) {
      absl::StrAppend(&list, list.size() > 1 ? "," : "",
                      "{\"path\":", JsonString(f.path),
                      ",\"reason\":", JsonString(f.reason), "}");
    }
    std::printf(
        "{\"files\":%zu,\"added\":%d,\"updated\":%d,\"skipped\":%zu,"
        "\"present\":%d,\"failed\":%zu,\"seconds\":%.3f,\"failures\":%s,"
        "\"skipped_files\":%s}\n",
        items.size(), added, updated, present + skipped.size(), present,
        failures->size(), seconds, FailuresJson(*failures).c_str(),
        (list + "]").c_str());
    return;
  }
  std::printf(
      "%zu mesh files: %d added, %d updated, %d already present, %zu failed "
      "in %.1f s\n",
      items.size(), added, updated, present, failures->size(), seconds);
  if (!skipped.empty()) std::printf("%zu files skipped:\n", skipped.size());
  for (const SkippedFile& f : skipped) {
    std::printf("  skipped %s: %s\n", TextField(f.path).c_str(),
                TextField(f.reason).c_str());
  }
  PrintFailures(*failures);
}

int RunAdd(const Globals& g, const AddFlags& flags) {
  AddOptions options = flags.options;
  options.media.set_thumbnail(!flags.no_media);
  options.media.set_thumbnail_overlay(!flags.no_media && !flags.no_overlay);
  options.media.set_preview(!flags.no_media);
  options.allow_duplicates = flags.allow_duplicates;
  std::vector<Item> items;
  std::vector<SkippedFile> skipped;
  if (std::optional<int> code = CollectItems(flags, &items, &skipped))
    return *code;
  std::optional<ExtractorClient> extractor = ConnectExtractor(g);
  if (!extractor) return 2;
  std::optional<IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 2;
  const tpr::client::CallOptions call = CallOptionsFor(g);

  Progress progress(items.size());
  absl::StatusOr<std::vector<AddOutcome>> outcomes =
      AddItems(*extractor, *indexer, items, options, call, &progress);
  if (!outcomes.ok()) return Fail("add", outcomes.status());
  Failures failures;
  PrintAddReport(g, items, *outcomes, std::move(skipped), progress.Elapsed(),
                 &failures);
  return failures.empty() ? 0 : 1;
}

const bool kRegistered = RegisterCommand(
    {"add",
     "index mesh files or folders (recursive); a mesh directly in a folder "
     "given gets the id FOLDER/FILE and the folder's name as label, a mesh in "
     "a subfolder its path below the folder given and the subfolder's name",
     [](CLI::App& sub) {
       auto flags = std::make_shared<AddFlags>();
       sub.add_option("PATH", flags->paths, "mesh files or folders")
           ->required();
       sub.add_option("--label", flags->naming.label,
                      "label every file with LABEL (default: its folder's "
                      "name)");
       sub.add_option("--id-prefix", flags->naming.id_prefix,
                      "put PREFIX before every id, e.g. shop/ (default: none)");
       sub.add_flag("--allow-duplicates", flags->allow_duplicates,
                    "add a file even when the same bytes are already indexed "
                    "under another id (default: skip it, saying which)");
       sub.add_option("--manifest", flags->manifest,
                      "file of 'RELATIVE/PATH LABEL' lines, paths relative to "
                      "the folder given");
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
     },
     "tpr add library/            # ids dog1/T305.obj ..., labels dog1 ..."});

}  // namespace

}  // namespace tpr::cli
