#include "indexer/service/indexer_core.h"

#include <chrono>
#include <cmath>
#include <unordered_map>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/status_macros.h"
#include "indexer/lib/ground_distance.h"

namespace tpr::indexer {
namespace {

int64_t NowMicros() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

absl::Status CheckId(const std::string& id) {
  if (id.empty()) return absl::InvalidArgumentError("model id is empty");
  if (id.size() > kMaxIdBytes) {
    return absl::InvalidArgumentError(absl::StrCat(
        "model id is ", id.size(), " bytes; at most ", kMaxIdBytes, " allowed"));
  }
  return absl::OkStatus();
}

}  // namespace

// The label of `id` in one published label map; nullptr when absent.
const std::string* IndexerCore::FindLabel(const LabelMap& labels, const std::string& id) {
  const LabelShard& shard = *labels[LabelShardOf(id)];
  auto it = shard.find(id);
  return it == shard.end() ? nullptr : &it->second;
}

void IndexerCore::ApplyLabelsLocked(
    const std::vector<std::pair<std::string, std::optional<std::string>>>& changes) {
  // Copy-on-write: only the shards touched are copied; the others are
  // shared with the previous map, which running searches may still hold.
  auto next = std::make_shared<LabelMap>(*labels_);
  std::unordered_map<size_t, LabelShard*> copied;
  for (const auto& [id, label] : changes) {
    const size_t at = LabelShardOf(id);
    LabelShard*& shard = copied[at];
    if (shard == nullptr) {
      auto copy = std::make_shared<LabelShard>(*(*next)[at]);
      shard = copy.get();
      (*next)[at] = std::move(copy);
    }
    if (label.has_value()) {
      (*shard)[id] = *label;
    } else {
      shard->erase(id);
    }
  }
  labels_ = std::move(next);
}

absl::StatusOr<tpr::index::Signature> ToIndexSignature(const tpr::v1::Signature& s) {
  if (s.features_size() > tpr::index::kMaxFeatures) {
    return absl::ResourceExhaustedError(
        absl::StrCat("signature has ", s.features_size(), " features; at most ",
                     tpr::index::kMaxFeatures, " are accepted"));
  }
  tpr::index::Signature out;
  out.features.reserve(static_cast<size_t>(s.features_size()));
  for (int i = 0; i < s.features_size(); ++i) {
    const tpr::v1::Feature& f = s.features(i);
    if (f.kind() != tpr::v1::FEATURE_KIND_POINT && f.kind() != tpr::v1::FEATURE_KIND_RING) {
      return absl::InvalidArgumentError(
          absl::StrCat("signature feature ", i, " has no kind (point or ring)"));
    }
    tpr::index::Feature g;
    g.weight = f.weight();
    g.g = f.integral_geodesic();
    g.k.assign(f.curvature().begin(), f.curvature().end());
    g.a.assign(f.area().begin(), f.area().end());
    g.h.assign(f.distance().begin(), f.distance().end());
    out.features.push_back(std::move(g));
  }
  absl::Status valid = tpr::index::ValidateSignature(out);
  if (!valid.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("malformed signature: ", valid.message()));
  }
  return out;
}

// ---------------------------------------------------------------------------
// Open and load.

IndexerCore::IndexerCore(CoreOptions options, std::unique_ptr<Storage> storage)
    : options_(std::move(options)), storage_(std::move(storage)) {}

absl::StatusOr<std::unique_ptr<IndexerCore>> IndexerCore::Open(CoreOptions options) {
  if (options.data_dir.empty()) {
    return absl::InvalidArgumentError("data directory is empty");
  }
  TPR_ASSIGN_OR_RETURN(std::unique_ptr<Storage> storage,
                       Storage::Open(options.data_dir, options.storage));
  std::unique_ptr<IndexerCore> core(new IndexerCore(std::move(options), std::move(storage)));
  TPR_RETURN_IF_ERROR(core->LoadIndex());
  if (core->options_.persist_interval_ms > 0) {
    core->persister_ = std::thread([c = core.get()] { c->PersisterLoop(); });
  }
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
    absl::MutexLock lock(&table_mu_);
    // Parsing and converting the stored signatures is most of the open's
    // CPU; two threads do it (the machine has two cores), and only the
    // cheap bookkeeping is serialized.
    std::mutex items_mu;
    TPR_RETURN_IF_ERROR(storage_->ForEachModel(
        [&](uint64_t seq, tpr::v1::Model&& model) -> absl::Status {
          absl::StatusOr<tpr::index::Signature> sig = ToIndexSignature(model.signature());
          if (!sig.ok()) {
            return absl::DataLossError(absl::StrCat("stored model '", model.id(),
                                                    "': ", sig.status().message()));
          }
          std::lock_guard<std::mutex> items_lock(items_mu);
          if (seq > marker) ++after_marker;
          Info& info = table_[model.id()];
          info.label = model.label();
          info.added_unix_micros = model.added_unix_micros();
          ++label_counts_[model.label()];
          items.emplace_back(std::move(*model.mutable_id()), std::move(*sig));
          return absl::OkStatus();
        },
        /*threads=*/2));
  }

  {
    // The label map searches use, built whole (no copy-on-write needed yet).
    std::vector<LabelShard> shards(kLabelShards);
    absl::ReaderMutexLock lock(&table_mu_);
    for (const auto& [id, info] : table_) shards[LabelShardOf(id)].emplace(id, info.label);
    auto labels = std::make_shared<LabelMap>();
    labels->reserve(kLabelShards);
    for (LabelShard& shard : shards) {
      labels->push_back(std::make_shared<const LabelShard>(std::move(shard)));
    }
    std::lock_guard<std::mutex> view(view_mu_);
    labels_ = std::move(labels);
  }

  if (tree.ok()) {
    absl::StatusOr<std::unique_ptr<tpr::index::SignatureIndex>> loaded =
        tpr::index::SignatureIndex::Load(tree->bytes, items, options_.index);
    if (loaded.ok()) {
      index_ = std::move(*loaded);
      persisted_hash_ = std::hash<std::string>()(tree->bytes);
      persisted_indexed_ = index_->indexed();
      persisted_buffered_ = index_->buffered();
      const double ms = std::chrono::duration<double, std::milli>(
                            std::chrono::steady_clock::now() - start)
                            .count();
      Log(absl::StrCat("opened ", items.size(), " models (", after_marker,
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
  TPR_ASSIGN_OR_RETURN(index_, tpr::index::SignatureIndex::Load(bytes, items, options_.index));
  if (!items.empty()) {
    TPR_RETURN_IF_ERROR(storage_->SaveTree(bytes, storage_->last_seq()));
  }
  persisted_hash_ = std::hash<std::string>()(bytes);
  persisted_indexed_ = index_->indexed();
  persisted_buffered_ = index_->buffered();
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
          .count();
  Log(absl::StrCat("opened ", items.size(), " models, VP-tree built in ",
                   static_cast<int64_t>(ms), " ms"));
  return absl::OkStatus();
}

IndexerCore::~IndexerCore() { Close(); }

void IndexerCore::Close() {
  {
    std::lock_guard<std::mutex> lock(stop_mu_);
    if (closed_) return;
    closed_ = true;
    stopping_ = true;
  }
  stop_cv_.notify_all();
  if (persister_.joinable()) persister_.join();
  if (index_ != nullptr) {
    absl::Status st = PersistTree();
    if (!st.ok()) Log(absl::StrCat("cannot persist the VP-tree at close: ", st.ToString()));
  }
}

void IndexerCore::PersisterLoop() {
  std::unique_lock<std::mutex> lock(stop_mu_);
  while (!stopping_) {
    stop_cv_.wait_for(lock, std::chrono::milliseconds(options_.persist_interval_ms));
    if (stopping_) break;
    lock.unlock();
    absl::Status st = PersistTree();
    if (!st.ok()) Log(absl::StrCat("cannot persist the VP-tree: ", st.ToString()));
    lock.lock();
  }
}

absl::Status IndexerCore::PersistTree() {
  std::lock_guard<std::mutex> lock(persist_mu_);
  const size_t indexed = index_->indexed();
  const size_t buffered = index_->buffered();
  // The tree only changes with a rebuild, which shows in these counts or
  // follows writes; without either there is nothing new to save.
  if (writes_since_persist_.load() == 0 && indexed == persisted_indexed_ &&
      buffered == persisted_buffered_) {
    return absl::OkStatus();
  }
  writes_since_persist_ = 0;
  // The marker is read before serializing (see Storage::SaveTree).
  const uint64_t seq = storage_->last_seq();
  const std::string bytes = index_->SerializeTree();
  const size_t hash = std::hash<std::string>()(bytes);
  persisted_indexed_ = indexed;
  persisted_buffered_ = buffered;
  if (hash == persisted_hash_) return absl::OkStatus();
  TPR_RETURN_IF_ERROR(storage_->SaveTree(bytes, seq));
  persisted_hash_ = hash;
  Log(absl::StrCat("persisted the VP-tree: ", indexed, " models, ", bytes.size(), " bytes"));
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------
// Writes.

absl::Status IndexerCore::CheckModel(const tpr::v1::Model& model,
                                     tpr::index::Signature* signature) const {
  TPR_RETURN_IF_ERROR(CheckId(model.id()));
  size_t metadata_bytes = 0;
  for (const auto& [key, value] : model.metadata()) metadata_bytes += key.size() + value.size();
  if (metadata_bytes > kMaxMetadataBytes) {
    return absl::ResourceExhaustedError(
        absl::StrCat("model '", model.id(), "' has ", metadata_bytes,
                     " bytes of metadata; at most ", kMaxMetadataBytes, " allowed"));
  }
  absl::StatusOr<tpr::index::Signature> sig = ToIndexSignature(model.signature());
  if (!sig.ok()) {
    return absl::Status(sig.status().code(),
                        absl::StrCat("model '", model.id(), "': ", sig.status().message()));
  }
  *signature = std::move(*sig);
  return absl::OkStatus();
}

absl::Status IndexerCore::WriteGroupLocked(
    std::vector<tpr::v1::UpsertRequest>& requests,
    std::vector<tpr::index::Signature>& signatures, std::vector<int>* outcome) {
  outcome->assign(requests.size(), kSkipped);
  // Ids written earlier in this same group, with their time added.
  std::unordered_map<std::string, int64_t> in_group;
  std::vector<ModelWrite> writes;
  writes.reserve(requests.size());
  const int64_t now = NowMicros();
  {
    absl::ReaderMutexLock lock(&table_mu_);
    for (size_t i = 0; i < requests.size(); ++i) {
      tpr::v1::Model* model = requests[i].mutable_model();
      bool exists = false;
      int64_t added = now;
      if (auto g = in_group.find(model->id()); g != in_group.end()) {
        exists = true;
        added = g->second;
      } else if (auto t = table_.find(model->id()); t != table_.end()) {
        exists = true;
        added = t->second.added_unix_micros;
      }
      if (exists && !requests[i].overwrite()) continue;
      // "When the model was first added": a replacement keeps the time.
      model->set_added_unix_micros(added);
      in_group[model->id()] = added;
      (*outcome)[i] = exists ? kReplaced : kCreated;
      writes.push_back({model->id(), model});
    }
  }
  if (writes.empty()) return absl::OkStatus();
  TPR_RETURN_IF_ERROR(storage_->Write(writes));
  // Durable from here on: the index (one bulk insert for the whole group:
  // per-model Upsert copies the index's buffer each time, which dominated
  // ingest), the label map and the table follow.
  std::vector<std::pair<std::string, tpr::index::Signature>> entries;
  std::vector<std::pair<std::string, std::optional<std::string>>> labels;
  entries.reserve(writes.size());
  labels.reserve(writes.size());
  for (size_t i = 0; i < requests.size(); ++i) {
    if ((*outcome)[i] == kSkipped) continue;
    const tpr::v1::Model& model = requests[i].model();
    entries.emplace_back(model.id(), std::move(signatures[i]));
    labels.emplace_back(model.id(), model.label());
  }
  {
    std::lock_guard<std::mutex> view(view_mu_);
    absl::Status st = index_->UpsertBatch(entries);
    if (!st.ok()) {
      // CheckModel validated the signatures already; this is a bug, not data.
      return absl::InternalError(
          absl::StrCat("index rejected a stored model: ", st.message()));
    }
    ApplyLabelsLocked(labels);
  }
  absl::MutexLock lock(&table_mu_);
  for (size_t i = 0; i < requests.size(); ++i) {
    if ((*outcome)[i] == kSkipped) continue;
    const tpr::v1::Model& model = requests[i].model();
    Info& info = table_[model.id()];
    if ((*outcome)[i] == kReplaced) {
      if (--label_counts_[info.label] == 0) label_counts_.erase(info.label);
    }
    info.label = model.label();
    info.added_unix_micros = model.added_unix_micros();
    ++label_counts_[model.label()];
  }
  writes_since_persist_ += writes.size();
  return absl::OkStatus();
}

absl::StatusOr<bool> IndexerCore::Upsert(const tpr::v1::UpsertRequest& request) {
  std::vector<tpr::index::Signature> signatures(1);
  TPR_RETURN_IF_ERROR(CheckModel(request.model(), &signatures[0]));
  std::vector<tpr::v1::UpsertRequest> requests = {request};
  std::vector<int> outcome;
  {
    std::lock_guard<std::mutex> lock(write_mu_);
    TPR_RETURN_IF_ERROR(WriteGroupLocked(requests, signatures, &outcome));
  }
  if (outcome[0] == kSkipped) {
    return absl::AlreadyExistsError(absl::StrCat(
        "model '", request.model().id(), "' exists; set overwrite to replace it"));
  }
  return outcome[0] == kCreated;
}

IndexerCore::BatchWriter::~BatchWriter() { Wait().IgnoreError(); }

absl::Status IndexerCore::BatchWriter::Add(tpr::v1::UpsertRequest request) {
  tpr::index::Signature signature;
  absl::Status valid = core_->CheckModel(request.model(), &signature);
  if (!valid.ok()) {
    // Keep the promise "models before the failing one are kept".
    TPR_RETURN_IF_ERROR(FlushAsync());
    TPR_RETURN_IF_ERROR(Wait());
    return valid;
  }
  pending_.push_back(std::move(request));
  signatures_.push_back(std::move(signature));
  if (pending_.size() >= core_->options_.batch_group) return FlushAsync();
  return absl::OkStatus();
}

absl::Status IndexerCore::BatchWriter::Wait() {
  if (inflight_.joinable()) inflight_.join();
  return inflight_status_;
}

absl::Status IndexerCore::BatchWriter::FlushAsync() {
  // One group in flight: its fsync overlaps receiving and validating the
  // next group, which the stream otherwise waited for (group commit alone
  // still stalled the stream for every fsync).
  TPR_RETURN_IF_ERROR(Wait());
  if (pending_.empty()) return absl::OkStatus();
  inflight_ = std::thread([this, requests = std::move(pending_),
                           signatures = std::move(signatures_)]() mutable {
    std::vector<int> outcome;
    absl::Status st;
    {
      std::lock_guard<std::mutex> lock(core_->write_mu_);
      st = core_->WriteGroupLocked(requests, signatures, &outcome);
    }
    if (st.ok()) {
      for (int o : outcome) {
        if (o == kSkipped) {
          counts_.set_skipped(counts_.skipped() + 1);
        } else {
          counts_.set_written(counts_.written() + 1);
        }
      }
    }
    inflight_status_ = st;
  });
  pending_.clear();
  signatures_.clear();
  return absl::OkStatus();
}

absl::StatusOr<tpr::v1::BatchUpsertResponse> IndexerCore::BatchWriter::Finish() {
  TPR_RETURN_IF_ERROR(FlushAsync());
  TPR_RETURN_IF_ERROR(Wait());
  return counts_;
}

absl::Status IndexerCore::Delete(const std::string& id) {
  TPR_RETURN_IF_ERROR(CheckId(id));
  std::lock_guard<std::mutex> lock(write_mu_);
  {
    absl::ReaderMutexLock read(&table_mu_);
    if (table_.find(id) == table_.end()) {
      return absl::NotFoundError(absl::StrCat("no model with id '", id, "'"));
    }
  }
  TPR_RETURN_IF_ERROR(storage_->Write({{id, nullptr}}));
  {
    std::lock_guard<std::mutex> view(view_mu_);
    index_->Remove(id);
    ApplyLabelsLocked({{id, std::nullopt}});
  }
  absl::MutexLock write(&table_mu_);
  auto it = table_.find(id);
  if (--label_counts_[it->second.label] == 0) label_counts_.erase(it->second.label);
  table_.erase(it);
  writes_since_persist_ += 1;
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------
// Reads.

absl::StatusOr<tpr::v1::Model> IndexerCore::Get(const std::string& id) const {
  TPR_RETURN_IF_ERROR(CheckId(id));
  return storage_->GetModel(id);
}

absl::StatusOr<tpr::v1::ListResponse> IndexerCore::List(
    const tpr::v1::ListRequest& request) const {
  if (request.page_size() < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("page_size is ", request.page_size(), "; it must be >= 0"));
  }
  const size_t page_size =
      request.page_size() == 0 ? 100 : std::min<size_t>(request.page_size(), 1000);
  std::vector<std::string> ids;
  bool more = false;
  {
    absl::ReaderMutexLock lock(&table_mu_);
    auto it = request.page_token().empty() ? table_.begin()
                                           : table_.upper_bound(request.page_token());
    for (; it != table_.end(); ++it) {
      if (!request.label().empty() && it->second.label != request.label()) continue;
      if (ids.size() == page_size) {
        more = true;
        break;
      }
      ids.push_back(it->first);
    }
  }
  tpr::v1::ListResponse response;
  for (const std::string& id : ids) {
    absl::StatusOr<tpr::v1::Model> model = storage_->GetModel(id);
    if (absl::IsNotFound(model.status())) continue;  // deleted meanwhile
    if (!model.ok()) return model.status();
    model->clear_signature();
    *response.add_models() = std::move(*model);
  }
  // The token is the last id of this page: ids are unique and ordered, so
  // the next page starts right after it whatever was written meanwhile.
  if (more && !ids.empty()) response.set_next_page_token(ids.back());
  return response;
}

tpr::v1::StatsResponse IndexerCore::Stats() const {
  tpr::v1::StatsResponse response;
  {
    absl::ReaderMutexLock lock(&table_mu_);
    response.set_models(static_cast<int64_t>(table_.size()));
    for (const auto& [label, count] : label_counts_) (*response.mutable_labels())[label] = count;
  }
  response.set_indexed(static_cast<int64_t>(index_->indexed()));
  response.set_buffered(static_cast<int64_t>(index_->buffered()));
  response.set_disk_bytes(storage_->DiskBytes());
  return response;
}

// ---------------------------------------------------------------------------
// Search.

namespace {

class Session final : public SearchSession {
 public:
  using LabelOf = std::function<std::string(const std::string&)>;
  Session(std::unique_ptr<tpr::index::SignatureIndex::Cursor> cursor, int k,
          std::function<bool()> cancelled, LabelOf label_of)
      : cursor_(std::move(cursor)),
        k_(k),
        cancelled_(std::move(cancelled)),
        label_of_(std::move(label_of)),
        start_(std::chrono::steady_clock::now()) {}

  std::optional<tpr::v1::Neighbor> Next() override {
    if (returned_ >= k_ || IsCancelled()) return std::nullopt;
    std::optional<tpr::index::Neighbor> n = cursor_->Next();
    // After a cancellation the filter rejected candidates unseen, so what the
    // cursor returns then is no longer the true next neighbour.
    if (!n.has_value() || IsCancelled()) return std::nullopt;
    tpr::v1::Neighbor out;
    out.set_rank(++returned_);
    out.set_label(label_of_(n->id));
    out.set_id(std::move(n->id));
    out.set_distance(n->distance);
    return out;
  }

  tpr::v1::SearchStats Stats() const override {
    tpr::v1::SearchStats stats;
    const tpr::index::SearchStats& s = cursor_->stats();
    stats.set_emd_computations(s.emd_computations);
    stats.set_lower_bounds(s.lower_bounds);
    stats.set_nodes_visited(s.nodes_visited);
    stats.set_milliseconds(std::chrono::duration<double, std::milli>(
                               std::chrono::steady_clock::now() - start_)
                               .count());
    return stats;
  }

 private:
  bool IsCancelled() const { return cancelled_ && cancelled_(); }

  std::unique_ptr<tpr::index::SignatureIndex::Cursor> cursor_;
  const int k_;
  int returned_ = 0;
  std::function<bool()> cancelled_;
  LabelOf label_of_;
  const std::chrono::steady_clock::time_point start_;
};

}  // namespace

absl::StatusOr<std::unique_ptr<SearchSession>> IndexerCore::StartSearch(
    const tpr::v1::SearchRequest& request, std::function<bool()> cancelled) const {
  if (request.k() < 1) {
    return absl::InvalidArgumentError(absl::StrCat("k is ", request.k(), "; it must be >= 1"));
  }
  if (request.k() > options_.max_k) {
    return absl::ResourceExhaustedError(
        absl::StrCat("k is ", request.k(), "; at most ", options_.max_k, " allowed"));
  }
  if (!(request.radius() >= 0.0) || !std::isfinite(request.radius())) {
    return absl::InvalidArgumentError(absl::StrCat(
        "radius is ", request.radius(), "; it must be finite and >= 0 (0: unlimited)"));
  }
  tpr::index::Signature query;
  std::string exclude;
  switch (request.query_case()) {
    case tpr::v1::SearchRequest::kSignature: {
      TPR_ASSIGN_OR_RETURN(query, ToIndexSignature(request.signature()));
      break;
    }
    case tpr::v1::SearchRequest::kId: {
      TPR_RETURN_IF_ERROR(CheckId(request.id()));
      TPR_ASSIGN_OR_RETURN(tpr::v1::Model model, storage_->GetModel(request.id()));
      absl::StatusOr<tpr::index::Signature> sig = ToIndexSignature(model.signature());
      if (!sig.ok()) {
        return absl::DataLossError(
            absl::StrCat("stored model '", request.id(), "': ", sig.status().message()));
      }
      query = std::move(*sig);
      if (request.exclude_self()) exclude = request.id();
      break;
    }
    default:
      return absl::InvalidArgumentError("search has no query: set signature or id");
  }
  const std::string label = request.label();
  std::unique_ptr<tpr::index::SignatureIndex::Cursor> cursor;
  Session::LabelOf label_of;
  {
    // The index snapshot and the label map are taken together (writers
    // update both under view_mu_), so filter and results use the labels that
    // went with the ranked signatures, whatever is written meanwhile.
    std::lock_guard<std::mutex> view(view_mu_);
    std::shared_ptr<const LabelMap> labels = labels_;
    auto filter = [labels, label, exclude, cancelled](const std::string& id) {
      if (cancelled && cancelled()) return false;
      if (!exclude.empty() && id == exclude) return false;
      if (label.empty()) return true;
      const std::string* found = FindLabel(*labels, id);
      return found != nullptr && *found == label;
    };
    label_of = [labels](const std::string& id) {
      const std::string* found = FindLabel(*labels, id);
      return found == nullptr ? std::string() : *found;
    };
    TPR_ASSIGN_OR_RETURN(cursor, index_->Search(query, request.radius(), filter));
  }
  return std::unique_ptr<SearchSession>(
      new Session(std::move(cursor), request.k(), std::move(cancelled), label_of));
}

}  // namespace tpr::indexer
