#include "indexer/service/indexer_core.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <set>
#include <thread>
#include <unordered_map>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/string_view.h"
#include "common/status_macros.h"
#include "indexer/gateway/shard_map.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/service/convert.h"

namespace tpr::indexer {
namespace {

int64_t NowMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// The id and label alphabet (indexer.proto): valid UTF-8 without control
// characters (U+0000..U+001F, U+007F..U+009F), so that every id prints on
// one line of `tpr list` and in logs. Returns the problem, naming `what`
// and the byte offset, or OK. Written by hand: the check needs the code
// points (for the C1 controls), which no Debian 12 library exposes
// publicly short of ICU. O(size).
absl::Status CheckText(absl::string_view text, absl::string_view what) {
  const auto* p = reinterpret_cast<const unsigned char*>(text.data());
  const size_t n = text.size();
  for (size_t i = 0; i < n;) {
    const unsigned char c = p[i];
    size_t len = 0;
    uint32_t cp = 0;
    if (c < 0x80) {
      len = 1;
      cp = c;
    } else if (c >= 0xc2 && c <= 0xdf) {
      len = 2;
      cp = c & 0x1f;
    } else if (c >= 0xe0 && c <= 0xef) {
      len = 3;
      cp = c & 0x0f;
    } else if (c >= 0xf0 && c <= 0xf4) {
      len = 4;
      cp = c & 0x07;
    }
    bool valid = len > 0 && i + len <= n;
    for (size_t k = 1; valid && k < len; ++k) {
      valid = (p[i + k] & 0xc0) == 0x80;
      cp = (cp << 6) | (p[i + k] & 0x3f);
    }
    // Overlong forms, surrogates and code points above U+10FFFF.
    if (valid && ((len == 3 && cp < 0x800) || (len == 4 && cp < 0x10000) ||
                  (cp >= 0xd800 && cp <= 0xdfff) || cp > 0x10ffff)) {
      valid = false;
    }
    if (!valid) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, " is not valid UTF-8 (byte ", i, ")"));
    }
    if (cp < 0x20 || (cp >= 0x7f && cp <= 0x9f)) {
      return absl::InvalidArgumentError(absl::StrCat(
          what, " holds control character ", absl::StrFormat("U+%04X", cp),
          " (byte ", i, "); ids and labels are printable UTF-8"));
    }
    i += len;
  }
  return absl::OkStatus();
}

absl::Status CheckId(const std::string& id) {
  if (id.empty()) return absl::InvalidArgumentError("model id is empty");
  if (id.size() > kMaxIdBytes) {
    return absl::InvalidArgumentError(absl::StrCat("model id is ", id.size(),
                                                   " bytes; at most ",
                                                   kMaxIdBytes, " allowed"));
  }
  return absl::OkStatus();
}

// Media are opaque bytes to the indexer; the checks keep an upload of the
// wrong file in the wrong field out (the first bytes of each format).
absl::Status CheckMedia(const tpr::v1::Model& model) {
  if (!model.has_media()) return absl::OkStatus();
  const std::string& png = model.media().thumbnail_png();
  const std::string& ply = model.media().preview_ply();
  if (png.size() > kMaxThumbnailBytes || ply.size() > kMaxPreviewBytes) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "model '", model.id(), "' has a ", png.size(), "-byte thumbnail and a ",
        ply.size(), "-byte preview; at most ", kMaxThumbnailBytes, " and ",
        kMaxPreviewBytes, " allowed"));
  }
  static constexpr char kPngMagic[] = "\x89PNG\r\n\x1a\n";
  if (!png.empty() && png.compare(0, 8, kPngMagic, 8) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "model '", model.id(), "': media.thumbnail_png is not a PNG image"));
  }
  if (!ply.empty() && ply.compare(0, 4, "ply\n") != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "model '", model.id(), "': media.preview_ply is not a PLY file"));
  }
  return absl::OkStatus();
}

// OpenThreads returns `requested`, or one per hardware thread when it is 0
// (at least 1).
int OpenThreads(int requested) {
  if (requested > 0) return requested;
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

}  // namespace

// ---------------------------------------------------------------------------
// Open and load.

IndexerCore::IndexerCore(CoreOptions options, std::unique_ptr<Storage> storage)
    : options_(std::move(options)),
      storage_(std::move(storage)),
      follow_(options_.follow) {}

absl::StatusOr<std::unique_ptr<IndexerCore>> IndexerCore::Open(
    CoreOptions options) {
  if (options.data_dir.empty()) {
    return absl::InvalidArgumentError("data directory is empty");
  }
  TPR_RETURN_IF_ERROR(tpr::index::ValidateIndexOptions(options.index));
  TPR_ASSIGN_OR_RETURN(std::unique_ptr<Storage> storage,
                       Storage::Open(options.data_dir, options.storage));
  std::unique_ptr<IndexerCore> core(
      new IndexerCore(std::move(options), std::move(storage)));
  TPR_RETURN_IF_ERROR(core->LoadIndex());
  core->persister_->Start();
  return core;
}

void IndexerCore::Log(const std::string& message) const {
  if (options_.log) options_.log(message);
}

absl::Status IndexerCore::LoadIndex() {
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<PersistedTree> tree = storage_->LoadTree();
  if (!tree.ok() && !absl::IsNotFound(tree.status())) return tree.status();
  const uint64_t marker = tree.ok() ? tree->seq : 0;

  std::vector<std::pair<std::string, tpr::index::Signature>> items;
  size_t after_marker = 0;
  {
    // Parsing and converting the stored signatures is most of the open's
    // CPU; options_.open_threads threads do it, and only the cheap
    // bookkeeping is serialized.
    tpr::common::Mutex items_mu;
    std::vector<std::pair<std::string, ModelInfo>> infos;
    std::set<std::string> outdated;
    TPR_RETURN_IF_ERROR(storage_->ForEachModel(
        [&](uint64_t seq, tpr::v1::Model&& model) -> absl::Status {
          absl::StatusOr<tpr::index::Signature> sig =
              ToIndexSignature(model.signature());
          if (absl::IsFailedPrecondition(sig.status())) {
            // Another signature version: kept, listed, not indexed.
            tpr::common::MutexLock items_lock(&items_mu);
            infos.push_back(
                {model.id(), {model.label(), model.added_unix_micros()}});
            outdated.insert(model.id());
            return absl::OkStatus();
          }
          if (!sig.ok()) {
            return absl::DataLossError(absl::StrCat(
                "stored model '", model.id(), "': ", sig.status().message()));
          }
          tpr::common::MutexLock items_lock(&items_mu);
          if (seq > marker) ++after_marker;
          infos.push_back(
              {model.id(), {model.label(), model.added_unix_micros()}});
          items.emplace_back(std::move(*model.mutable_id()), std::move(*sig));
          return absl::OkStatus();
        },
        OpenThreads(options_.open_threads)));
    // The scan must find every model the acknowledged writes left.
    TPR_RETURN_IF_ERROR(storage_->CheckScanned(items.size() + outdated.size()));
    if (!items.empty()) {
      TPR_RETURN_IF_ERROR(CheckBands(items.front().second, /*fix=*/true));
    }
    table_.Put(infos);
    if (!outdated.empty()) {
      Log(absl::StrCat(
          outdated.size(), " stored models (e.g. '", *outdated.begin(),
          "') have an older signature version; they are kept but not searched "
          "until re-extracted with `tpr add --update`"));
    }
    tpr::common::MutexLock view(&view_mu_);
    outdated_ = std::move(outdated);
  }
  {
    // The label map searches use, built whole (no copy-on-write needed yet).
    LabelMap labels(table_.IdLabels());
    tpr::common::MutexLock view(&view_mu_);
    labels_ = std::move(labels);
  }

  TreePersisterOptions persister_options;
  persister_options.interval_ms = options_.persist_interval_ms;
  persister_options.log = options_.log;
  if (tree.ok()) {
    absl::StatusOr<std::unique_ptr<tpr::index::SignatureIndex>> loaded =
        tpr::index::SignatureIndex::Load(tree->bytes, items, options_.index);
    if (loaded.ok()) {
      index_ = std::move(*loaded);
      persister_ = std::make_unique<TreePersister>(
          storage_.get(), index_.get(), std::move(persister_options));
      persister_->MarkSaved(tree->bytes);
      const double ms = std::chrono::duration<double, std::milli>(
                            std::chrono::steady_clock::now() - start)
                            .count();
      Log(absl::StrCat(
          "opened ", items.size(), " models (", after_marker,
          " written after the last tree persist) from the persisted "
          "VP-tree in ",
          static_cast<int64_t>(ms), " ms"));
      return absl::OkStatus();
    }
    Log(absl::StrCat("persisted VP-tree unusable (", loaded.status().ToString(),
                     "); building the tree from the models"));
  }

  // No usable tree: build one once, without the background rebuilds that
  // inserting model by model would trigger, then load it like a persisted one
  // so the live index has the configured options.
  tpr::index::IndexOptions build_options = options_.index;
  build_options.background_rebuild = false;
  build_options.rebuild_threshold = items.size() + 1;
  tpr::index::SignatureIndex builder(build_options);
  // One bulk insert: per-item Upsert copies the growing buffer each time,
  // quadratic in the number of models.
  TPR_RETURN_IF_ERROR(builder.UpsertBatch(items));
  builder.Rebuild();
  const std::string bytes = builder.SerializeTree();
  TPR_ASSIGN_OR_RETURN(
      index_, tpr::index::SignatureIndex::Load(bytes, items, options_.index));
  if (!items.empty()) {
    TPR_RETURN_IF_ERROR(storage_->SaveTree(bytes, storage_->last_seq()));
  }
  persister_ = std::make_unique<TreePersister>(storage_.get(), index_.get(),
                                               std::move(persister_options));
  persister_->MarkSaved(bytes);
  const double ms = std::chrono::duration<double, std::milli>(
                        std::chrono::steady_clock::now() - start)
                        .count();
  Log(absl::StrCat("opened ", items.size(), " models, VP-tree built in ",
                   static_cast<int64_t>(ms), " ms"));
  return absl::OkStatus();
}

IndexerCore::~IndexerCore() { Close(); }

void IndexerCore::Close() {
  if (persister_ != nullptr) persister_->Stop();
}

// ---------------------------------------------------------------------------
// Writes.

absl::Status IndexerCore::CheckModel(const tpr::v1::Model& model,
                                     tpr::index::Signature* signature) const {
  TPR_RETURN_IF_ERROR(CheckId(model.id()));
  // Ids and labels are checked against the alphabet when written; reads,
  // deletes and searches by id accept any id already stored.
  TPR_RETURN_IF_ERROR(CheckText(model.id(), "model id"));
  if (absl::Status label = CheckText(model.label(), "label"); !label.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("model '", model.id(), "': ", label.message()));
  }
  if (model.label().size() > kMaxLabelBytes) {
    return absl::InvalidArgumentError(absl::StrCat(
        "model '", model.id(), "' has a label of ", model.label().size(),
        " bytes; at most ", kMaxLabelBytes, " allowed"));
  }
  size_t metadata_bytes = 0;
  for (const auto& [key, value] : model.metadata())
    metadata_bytes += key.size() + value.size();
  if (metadata_bytes > kMaxMetadataBytes) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "model '", model.id(), "' has ", metadata_bytes,
        " bytes of metadata; at most ", kMaxMetadataBytes, " allowed"));
  }
  TPR_RETURN_IF_ERROR(CheckMedia(model));
  absl::StatusOr<tpr::index::Signature> sig =
      ToIndexSignature(model.signature());
  if (!sig.ok()) {
    return absl::Status(
        sig.status().code(),
        absl::StrCat("model '", model.id(), "': ", sig.status().message()));
  }
  if (absl::Status bands = CheckBands(*sig, /*fix=*/true); !bands.ok()) {
    return absl::Status(bands.code(), absl::StrCat("model '", model.id(),
                                                   "': ", bands.message()));
  }
  *signature = std::move(*sig);
  return absl::OkStatus();
}

absl::Status IndexerCore::CheckBands(const tpr::index::Signature& s,
                                     bool fix) const {
  if (s.features.empty()) return absl::OkStatus();
  const int bands = static_cast<int>(s.features.front().curvature.size());
  int known = bands_.load();
  if (known == 0 && fix && bands_.compare_exchange_strong(known, bands)) {
    return absl::OkStatus();
  }
  if (known == 0 || known == bands) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      "signature options.bands is ", bands, "; this index holds signatures of ",
      known, " bands (extract with the same options as the stored models)"));
}

absl::StatusOr<std::vector<WriteOutcome>> IndexerCore::WriteGroup(
    std::vector<tpr::v1::UpsertRequest>& requests,
    std::vector<tpr::index::Signature>& signatures) {
  tpr::common::MutexLock lock(&write_mu_);
  return WriteGroupLocked(requests, signatures);
}

absl::StatusOr<std::vector<WriteOutcome>> IndexerCore::WriteGroupLocked(
    std::vector<tpr::v1::UpsertRequest>& requests,
    std::vector<tpr::index::Signature>& signatures) {
  TPR_RETURN_IF_ERROR(CheckWritable());
  std::vector<WriteOutcome> outcome(requests.size(), WriteOutcome::kSkipped);
  // Ids written earlier in this same group, with their time added.
  std::unordered_map<std::string, int64_t> in_group;
  std::vector<ModelWrite> writes;
  writes.reserve(requests.size());
  // Each written model's media, moved out of the request: the models
  // family stores the model without them.
  std::vector<tpr::v1::ModelMedia> media(requests.size());
  const int64_t now = NowMicros();
  for (size_t i = 0; i < requests.size(); ++i) {
    tpr::v1::Model* model = requests[i].mutable_model();
    std::optional<int64_t> added;
    if (auto g = in_group.find(model->id()); g != in_group.end()) {
      added = g->second;
    } else {
      added = table_.AddedTime(model->id());
    }
    const bool exists = added.has_value();
    if (exists && !requests[i].overwrite()) continue;
    // "When the model was first added": a replacement keeps the time.
    model->set_added_unix_micros(added.value_or(now));
    in_group[model->id()] = model->added_unix_micros();
    outcome[i] = exists ? WriteOutcome::kReplaced : WriteOutcome::kCreated;
    if (model->has_media()) {
      media[i] = std::move(*model->mutable_media());
      model->clear_media();
    }
    model->set_media_stored(!media[i].thumbnail_png().empty() ||
                            !media[i].preview_ply().empty());
    writes.push_back({model->id(), model, &media[i]});
  }
  if (writes.empty()) return outcome;
  TPR_RETURN_IF_ERROR(storage_->Write(writes));
  // Durable from here on: the index (one bulk insert for the whole group:
  // per-model Upsert copies the index's buffer each time, which dominated
  // ingest), the label map and the table follow.
  std::vector<std::pair<std::string, tpr::index::Signature>> entries;
  std::vector<LabelChange> labels;
  std::vector<std::pair<std::string, ModelInfo>> infos;
  entries.reserve(writes.size());
  labels.reserve(writes.size());
  infos.reserve(writes.size());
  for (size_t i = 0; i < requests.size(); ++i) {
    if (outcome[i] == WriteOutcome::kSkipped) continue;
    const tpr::v1::Model& model = requests[i].model();
    entries.emplace_back(model.id(), std::move(signatures[i]));
    labels.emplace_back(model.id(), model.label());
    infos.push_back({model.id(), {model.label(), model.added_unix_micros()}});
  }
  {
    tpr::common::MutexLock view(&view_mu_);
    absl::Status st = index_->UpsertBatch(entries);
    if (!st.ok()) {
      // CheckModel validated the signatures already; this is a bug, not data.
      return absl::InternalError(
          absl::StrCat("index rejected a stored model: ", st.message()));
    }
    labels_.Apply(labels);
    for (const auto& entry : entries) outdated_.erase(entry.first);
  }
  table_.Put(infos);
  persister_->NoteWrites(writes.size());
  return outcome;
}

absl::StatusOr<bool> IndexerCore::Upsert(
    const tpr::v1::UpsertRequest& request) {
  std::vector<tpr::index::Signature> signatures(1);
  TPR_RETURN_IF_ERROR(CheckModel(request.model(), &signatures[0]));
  std::vector<tpr::v1::UpsertRequest> requests = {request};
  TPR_ASSIGN_OR_RETURN(std::vector<WriteOutcome> outcome,
                       WriteGroup(requests, signatures));
  if (outcome[0] == WriteOutcome::kSkipped) {
    return absl::AlreadyExistsError(
        absl::StrCat("model '", request.model().id(),
                     "' exists; set overwrite to replace it"));
  }
  return outcome[0] == WriteOutcome::kCreated;
}

absl::Status IndexerCore::Delete(const std::string& id) {
  TPR_RETURN_IF_ERROR(CheckId(id));
  tpr::common::MutexLock lock(&write_mu_);
  TPR_RETURN_IF_ERROR(CheckWritable());
  if (!table_.AddedTime(id).has_value()) {
    return absl::NotFoundError(absl::StrCat("no model with id '", id, "'"));
  }
  TPR_RETURN_IF_ERROR(storage_->Write({{id, nullptr}}));
  {
    tpr::common::MutexLock view(&view_mu_);
    index_->Remove(id);
    labels_.Apply({{id, std::nullopt}});
    outdated_.erase(id);
  }
  table_.Erase(id);
  persister_->NoteWrites(1);
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------
// Reads.

absl::StatusOr<tpr::v1::Model> IndexerCore::Get(const std::string& id) const {
  TPR_RETURN_IF_ERROR(CheckId(id));
  return storage_->GetModel(id);
}

absl::StatusOr<tpr::v1::ModelMedia> IndexerCore::MediaOf(
    const std::string& id, const char* what) const {
  TPR_RETURN_IF_ERROR(CheckId(id));
  if (!table_.AddedTime(id).has_value()) {
    return absl::NotFoundError(absl::StrCat("no model with id '", id, "'"));
  }
  absl::StatusOr<tpr::v1::ModelMedia> media = storage_->GetMedia(id);
  if (absl::IsNotFound(media.status())) media = tpr::v1::ModelMedia();
  if (!media.ok()) return media.status();
  const bool missing = std::string(what) == "thumbnail"
                           ? media->thumbnail_png().empty()
                           : media->preview_ply().empty();
  if (missing) {
    return absl::NotFoundError(absl::StrCat(
        "model '", id, "' has no ", what,
        " (it was added without media; `tpr add --update` makes them)"));
  }
  return media;
}

absl::StatusOr<std::string> IndexerCore::GetThumbnail(
    const std::string& id) const {
  TPR_ASSIGN_OR_RETURN(tpr::v1::ModelMedia media, MediaOf(id, "thumbnail"));
  return std::move(*media.mutable_thumbnail_png());
}

absl::StatusOr<std::string> IndexerCore::GetPreview(
    const std::string& id) const {
  TPR_ASSIGN_OR_RETURN(tpr::v1::ModelMedia media, MediaOf(id, "preview"));
  return std::move(*media.mutable_preview_ply());
}

absl::StatusOr<tpr::v1::ListResponse> IndexerCore::List(
    const tpr::v1::ListRequest& request) const {
  if (request.page_size() < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "page_size is ", request.page_size(), "; it must be >= 0"));
  }
  const size_t page_size = request.page_size() == 0
                               ? 100
                               : std::min<size_t>(request.page_size(), 1000);
  TPR_ASSIGN_OR_RETURN(
      const std::string after,
      tpr::gateway::DecodeIndexerListToken(request.page_token()));
  bool more = false;
  const std::vector<std::string> ids =
      table_.Page(after, request.label(), page_size, &more);
  tpr::v1::ListResponse response;
  size_t bytes = 0;
  const std::string* last = nullptr;
  for (const std::string& id : ids) {
    absl::StatusOr<tpr::v1::Model> model = storage_->GetModel(id);
    if (absl::IsNotFound(model.status())) continue;  // deleted meanwhile
    if (!model.ok()) return model.status();
    model->clear_signature();
    // Bounded by construction: the page stops before kMaxListPageBytes, and
    // one model is at most ~66 KiB (CheckModel's limits), so the answer
    // stays far below gRPC's default 4 MiB receive limit. The framing of a
    // repeated field adds at most 6 bytes per model.
    const size_t model_bytes = model->ByteSizeLong() + 6;
    if (bytes + model_bytes > kMaxListPageBytes && response.models_size() > 0) {
      more = true;
      break;
    }
    bytes += model_bytes;
    last = &id;
    *response.add_models() = std::move(*model);
  }
  // The token seals the last id of this page: ids are unique and ordered,
  // so the next page starts right after it whatever was written meanwhile.
  // (When every id of the page was deleted meanwhile, the page's last id.)
  if (more && last == nullptr && !ids.empty()) last = &ids.back();
  if (more && last != nullptr)
    response.set_next_page_token(tpr::gateway::EncodeIndexerListToken(*last));
  return response;
}

tpr::v1::StatsResponse IndexerCore::Stats() const {
  tpr::v1::StatsResponse response;
  response.set_models(static_cast<int64_t>(table_.size()));
  for (const auto& [label, count] : table_.TopLabels(kMaxStatsLabels)) {
    (*response.mutable_labels())[label] = count;
  }
  response.set_indexed(static_cast<int64_t>(index_->indexed()));
  response.set_buffered(static_cast<int64_t>(index_->buffered()));
  response.set_memory_bytes(static_cast<int64_t>(index_->MemoryBytes()));
  response.set_disk_bytes(storage_->DiskBytes());
  return response;
}

// ---------------------------------------------------------------------------
// Search.

absl::StatusOr<std::unique_ptr<SearchSession>> IndexerCore::StartSearch(
    const tpr::v1::SearchRequest& request,
    std::function<bool()> cancelled) const {
  if (request.k() < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("k is ", request.k(), "; it must be >= 1"));
  }
  if (request.k() > options_.max_k) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "k is ", request.k(), "; at most ", options_.max_k, " allowed"));
  }
  if (!(request.radius() >= 0.0) || !std::isfinite(request.radius())) {
    return absl::InvalidArgumentError(
        absl::StrCat("radius is ", request.radius(),
                     "; it must be finite and >= 0 (0: unlimited)"));
  }
  TPR_ASSIGN_OR_RETURN(const tpr::index::TermWeights weights,
                       ToTermWeights(request));
  tpr::index::Signature query;
  std::string exclude;
  switch (request.query_case()) {
    case tpr::v1::SearchRequest::kSignature: {
      TPR_ASSIGN_OR_RETURN(query, ToIndexSignature(request.signature()));
      TPR_RETURN_IF_ERROR(CheckBands(query, /*fix=*/false));
      break;
    }
    case tpr::v1::SearchRequest::kId: {
      TPR_RETURN_IF_ERROR(CheckId(request.id()));
      TPR_ASSIGN_OR_RETURN(tpr::v1::Model model,
                           storage_->GetModel(request.id()));
      absl::StatusOr<tpr::index::Signature> sig =
          ToIndexSignature(model.signature());
      if (absl::IsFailedPrecondition(sig.status())) {
        return absl::FailedPreconditionError(absl::StrCat(
            "stored model '", request.id(), "': ", sig.status().message()));
      }
      if (!sig.ok()) {
        return absl::DataLossError(absl::StrCat("stored model '", request.id(),
                                                "': ", sig.status().message()));
      }
      query = std::move(*sig);
      if (request.exclude_self()) exclude = request.id();
      break;
    }
    default:
      return absl::InvalidArgumentError(
          "search has no query: set signature or id");
  }
  const std::string label = request.label();
  std::unique_ptr<tpr::index::SignatureIndex::Cursor> cursor;
  std::shared_ptr<const LabelSnapshot> labels;
  {
    // The index snapshot and the label map are taken together (writers
    // update both under view_mu_), so filter and results use the labels that
    // went with the ranked signatures, whatever is written meanwhile.
    tpr::common::MutexLock view(&view_mu_);
    if (!outdated_.empty()) {
      return absl::FailedPreconditionError(absl::StrCat(
          outdated_.size(), " stored models (e.g. '", *outdated_.begin(),
          "') have an older signature version and cannot be compared with the "
          "others; "
          "re-extract them with `tpr add --update` (nothing was lost: they are "
          "kept "
          "and listed until replaced)"));
    }
    labels = labels_.snapshot();
    auto filter = [labels, label, exclude](const std::string& id) {
      if (!exclude.empty() && id == exclude) return false;
      if (label.empty()) return true;
      const std::string* found = labels->Find(id);
      return found != nullptr && *found == label;
    };
    // Cancellation is polled between EMDs inside the ranked search: one
    // cursor step may otherwise run many EMDs (a filtered or far-reaching
    // search), which kept the server busy after the client's deadline.
    // Every weighting (intent or ranking) is searched with the tree.
    TPR_ASSIGN_OR_RETURN(
        cursor,
        index_->Search(query, weights, request.radius(), filter, cancelled));
  }
  return MakeSearchSession(std::move(cursor), request.k(), std::move(cancelled),
                           std::move(labels));
}

}  // namespace tpr::indexer
