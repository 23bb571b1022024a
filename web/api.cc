#include "web/api.h"

#include <google/protobuf/util/json_util.h>
#include <httplib.h>

#include <chrono>
#include <cmath>
#include <future>
#include <optional>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "web/http_errors.h"

namespace tpr::web {
namespace {

using Clock = std::chrono::steady_clock;

std::string ToJson(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  // Zero distances, ranks and counts are printed rather than left out, so a
  // client need not know proto3's defaults.
  options.always_print_primitive_fields = true;
  std::string out;
  // Cannot fail for a message we built (no Any, no invalid UTF-8 from the
  // services, which validate their strings).
  (void)google::protobuf::util::MessageToJsonString(message, &out, options);
  return out;
}

Reply JsonReply(std::string body) {
  Reply reply;
  reply.body = std::move(body);
  reply.content_type = kJsonType;
  return reply;
}

Reply BytesReply(std::string body, const char* content_type) {
  Reply reply;
  reply.body = std::move(body);
  reply.content_type = content_type;
  // A model's pictures change only on an update with new media.
  reply.headers.emplace_back("Cache-Control", "private, max-age=60");
  return reply;
}

// Param returns a query parameter, else a multipart form field (not a
// file) of that name.
std::optional<std::string> Param(const httplib::Request& request,
                                 const char* name) {
  if (request.has_param(name)) return request.get_param_value(name);
  if (request.has_file(name)) {
    const httplib::MultipartFormData field = request.get_file_value(name);
    if (field.filename.empty()) return field.content;
  }
  return std::nullopt;
}

absl::Status BadParam(absl::string_view name, absl::string_view value,
                      absl::string_view expected) {
  return absl::InvalidArgumentError(
      absl::StrCat(name, ": '", value.substr(0, 64), "' is not ", expected));
}

absl::Status ParseIntParam(const httplib::Request& request, const char* name,
                           int min, int max, int* out) {
  std::optional<std::string> text = Param(request, name);
  if (!text) return absl::OkStatus();
  int value = 0;
  if (!absl::SimpleAtoi(*text, &value) || value < min || value > max) {
    return BadParam(name, *text,
                    absl::StrCat("an integer in [", min, ", ", max, "]"));
  }
  *out = value;
  return absl::OkStatus();
}

absl::Status ParseDoubleParam(const httplib::Request& request, const char* name,
                              double* out) {
  std::optional<std::string> text = Param(request, name);
  if (!text) return absl::OkStatus();
  double value = 0;
  if (!absl::SimpleAtod(*text, &value) || !std::isfinite(value) || value < 0)
    return BadParam(name, *text, "a finite number >= 0");
  *out = value;
  return absl::OkStatus();
}

absl::Status ParseBoolParam(const httplib::Request& request, const char* name,
                            bool* out) {
  std::optional<std::string> text = Param(request, name);
  if (!text) return absl::OkStatus();
  const std::string v = absl::AsciiStrToLower(*text);
  if (v == "1" || v == "true" || v == "yes" || v == "on") {
    *out = true;
  } else if (v == "0" || v == "false" || v == "no" || v == "off") {
    *out = false;
  } else {
    return BadParam(name, *text, "a boolean (1, 0, true, false)");
  }
  return absl::OkStatus();
}

// ParseIntent accepts "identity", "kind", "balanced" or the enum's own
// names ("INTENT_KIND").
absl::Status ParseIntentParam(const httplib::Request& request,
                              v1::Intent* out) {
  std::optional<std::string> text = Param(request, "intent");
  if (!text || text->empty()) return absl::OkStatus();
  std::string name = absl::AsciiStrToUpper(*text);
  if (name.rfind("INTENT_", 0) != 0) name = "INTENT_" + name;
  v1::Intent intent;
  if (!v1::Intent_Parse(name, &intent))
    return BadParam("intent", *text, "one of balanced, identity, kind");
  *out = intent;
  return absl::OkStatus();
}

// ParseSearchParams reads k, radius, label, intent and exclude_self into
// `*request`.
absl::Status ParseSearchParams(const httplib::Request& request,
                               const ApiOptions& options,
                               v1::SearchRequest* search) {
  int k = options.default_k;
  if (absl::Status s = ParseIntParam(request, "k", 1, options.max_k, &k);
      !s.ok())
    return s;
  search->set_k(k);
  double radius = 0;
  if (absl::Status s = ParseDoubleParam(request, "radius", &radius); !s.ok())
    return s;
  search->set_radius(radius);
  if (std::optional<std::string> label = Param(request, "label"))
    search->set_label(*label);
  v1::Intent intent = v1::INTENT_UNSPECIFIED;
  if (absl::Status s = ParseIntentParam(request, &intent); !s.ok()) return s;
  search->set_intent(intent);
  bool exclude_self = false;
  if (absl::Status s = ParseBoolParam(request, "exclude_self", &exclude_self);
      !s.ok())
    return s;
  search->set_exclude_self(exclude_self);
  return absl::OkStatus();
}

// Upload: the mesh of a request, as a multipart file field "mesh" or as
// the raw body (file name from ?file_name=).
struct Upload {
  std::string bytes;
  std::string file_name;
  v1::MeshFormat format = v1::MESH_FORMAT_UNSPECIFIED;
};

absl::StatusOr<Upload> ReadUpload(const httplib::Request& request) {
  Upload upload;
  if (request.is_multipart_form_data()) {
    if (!request.has_file("mesh")) {
      return absl::InvalidArgumentError(
          "no mesh: the multipart form has no file field named 'mesh'");
    }
    httplib::MultipartFormData file = request.get_file_value("mesh");
    upload.bytes = std::move(file.content);
    upload.file_name = std::move(file.filename);
  } else {
    upload.bytes = request.body;
    upload.file_name = Param(request, "file_name").value_or("");
  }
  if (upload.bytes.empty()) {
    return absl::InvalidArgumentError(
        "no mesh: send the file as multipart field 'mesh' or as the request "
        "body (with ?file_name=NAME.off)");
  }
  if (std::optional<std::string> format = Param(request, "format")) {
    const std::string name = "MESH_FORMAT_" + absl::AsciiStrToUpper(*format);
    if (!v1::MeshFormat_Parse(name, &upload.format))
      return BadParam("format", *format, "one of off, obj, ply, stl");
  }
  return upload;
}

std::string NeighborsJson(const SearchResult& result) {
  std::string out = "\"neighbors\":[";
  for (size_t i = 0; i < result.neighbors.size(); ++i) {
    absl::StrAppend(&out, i ? "," : "", ToJson(result.neighbors[i]));
  }
  absl::StrAppend(&out, "],\"stats\":", ToJson(result.stats));
  return out;
}

// The handlers, sharing the backends, the search log and the options.
class Handlers {
 public:
  Handlers(const Backends* backends, RecentSearches* searches,
           ApiOptions options)
      : backends_(backends), searches_(searches), options_(options) {}

  Reply SearchById(const httplib::Request& request, const CallMeta& meta) {
    const Clock::time_point start = Clock::now();
    std::optional<std::string> id = Param(request, "id");
    if (!id || id->empty()) {
      return ErrorReply(absl::InvalidArgumentError(
                            "id: missing (GET /api/v1/search?id=ID searches "
                            "by a stored model; POST uploads a mesh)"),
                        meta.request_id);
    }
    v1::SearchRequest search;
    search.set_id(*id);
    if (absl::Status s = ParseSearchParams(request, options_, &search); !s.ok())
      return ErrorReply(s, meta.request_id);
    return RunSearch(search, meta, start, "");
  }

  Reply SearchPost(const httplib::Request& request, const CallMeta& meta) {
    const Clock::time_point start = Clock::now();
    const std::string type = request.get_header_value("Content-Type");
    if (type.rfind("application/json", 0) == 0) {
      v1::SearchRequest search;
      google::protobuf::util::JsonParseOptions parse;
      const auto parsed = google::protobuf::util::JsonStringToMessage(
          request.body, &search, parse);
      if (!parsed.ok()) {
        return ErrorReply(absl::InvalidArgumentError(absl::StrCat(
                              "body is not a tpr.v1.SearchRequest: ",
                              parsed.message().ToString())),
                          meta.request_id);
      }
      if (search.k() == 0) search.set_k(options_.default_k);
      return RunSearch(search, meta, start, "");
    }
    absl::StatusOr<Upload> upload = ReadUpload(request);
    if (!upload.ok()) return ErrorReply(upload.status(), meta.request_id);
    v1::SearchRequest search;
    if (absl::Status s = ParseSearchParams(request, options_, &search); !s.ok())
      return ErrorReply(s, meta.request_id);
    v1::ExtractOptions extract;
    bool explain = false;
    v1::MediaOptions media;
    bool preview = false, thumbnail = false;
    for (const auto& [name, target] :
         {std::pair<const char*, bool*>{"explain", &explain},
          {"preview", &preview},
          {"thumbnail", &thumbnail}}) {
      if (absl::Status s = ParseBoolParam(request, name, target); !s.ok())
        return ErrorReply(s, meta.request_id);
    }
    extract.set_explain(explain);
    media.set_preview(preview);
    media.set_thumbnail(thumbnail);
    media.set_thumbnail_overlay(thumbnail);
    absl::StatusOr<v1::ExtractResponse> extracted = backends_->Extract(
        upload->bytes, upload->file_name, upload->format, extract, media, meta);
    if (!extracted.ok()) return ErrorReply(extracted.status(), meta.request_id);
    *search.mutable_signature() = extracted->signature();
    return RunSearch(search, meta, start, ToJson(*extracted));
  }

  Reply GetModel(const httplib::Request& request, const CallMeta& meta) {
    absl::StatusOr<v1::Model> model =
        backends_->Get(request.matches[1].str(), meta);
    if (!model.ok()) return ErrorReply(model.status(), meta.request_id);
    return JsonReply(ToJson(*model));
  }

  Reply ListModels(const httplib::Request& request, const CallMeta& meta) {
    v1::ListRequest list;
    int page_size = 100;
    if (absl::Status s =
            ParseIntParam(request, "page_size", 1, 1000, &page_size);
        !s.ok())
      return ErrorReply(s, meta.request_id);
    list.set_page_size(page_size);
    list.set_page_token(Param(request, "page_token").value_or(""));
    list.set_label(Param(request, "label").value_or(""));
    absl::StatusOr<v1::ListResponse> page = backends_->List(list, meta);
    if (!page.ok()) return ErrorReply(page.status(), meta.request_id);
    return JsonReply(ToJson(*page));
  }

  Reply AddModel(const httplib::Request& request, const CallMeta& meta) {
    std::optional<std::string> id = Param(request, "id");
    if (!id || id->empty()) {
      return ErrorReply(absl::InvalidArgumentError("id: missing"),
                        meta.request_id);
    }
    bool overwrite = false;
    if (absl::Status s = ParseBoolParam(request, "overwrite", &overwrite);
        !s.ok())
      return ErrorReply(s, meta.request_id);
    absl::StatusOr<Upload> upload = ReadUpload(request);
    if (!upload.ok()) return ErrorReply(upload.status(), meta.request_id);
    v1::MediaOptions media;
    media.set_thumbnail(true);
    media.set_preview(true);
    absl::StatusOr<v1::ExtractResponse> extracted =
        backends_->Extract(upload->bytes, upload->file_name, upload->format,
                           v1::ExtractOptions(), media, meta);
    if (!extracted.ok()) return ErrorReply(extracted.status(), meta.request_id);
    v1::Model model;
    model.set_id(*id);
    model.set_label(Param(request, "label").value_or(""));
    *model.mutable_signature() = extracted->signature();
    *model.mutable_media() = extracted->media();
    absl::StatusOr<bool> created = backends_->Upsert(model, overwrite, meta);
    if (!created.ok()) return ErrorReply(created.status(), meta.request_id);
    v1::UpsertResponse response;
    response.set_created(*created);
    Reply reply = JsonReply(ToJson(response));
    if (*created) reply.http_status = 201;
    return reply;
  }

  Reply DeleteModel(const httplib::Request& request, const CallMeta& meta) {
    absl::Status s = backends_->Delete(request.matches[1].str(), meta);
    if (!s.ok()) return ErrorReply(s, meta.request_id);
    return JsonReply("{}");
  }

  Reply Stats(const httplib::Request&, const CallMeta& meta) {
    absl::StatusOr<v1::StatsResponse> stats = backends_->Stats(meta);
    if (!stats.ok()) return ErrorReply(stats.status(), meta.request_id);
    return JsonReply(ToJson(*stats));
  }

  Reply Status(const httplib::Request&, const CallMeta& meta) {
    // The three calls are independent: run them side by side, so a service
    // that is down costs one deadline, not three.
    auto extractor = std::async(
        std::launch::async, [this] { return backends_->ExtractorReadiness(); });
    auto indexer = std::async(std::launch::async,
                              [this] { return backends_->IndexerReadiness(); });
    absl::StatusOr<v1::StatsResponse> stats = backends_->Stats(meta);
    const std::string extractor_reason = extractor.get();
    const std::string indexer_reason = indexer.get();
    // A refused key is the caller's problem, not a state of the services.
    if (absl::IsUnauthenticated(stats.status()) ||
        absl::IsPermissionDenied(stats.status()))
      return ErrorReply(stats.status(), meta.request_id);
    auto service = [](const std::string& address, const std::string& reason) {
      return absl::StrCat("{\"address\":", JsonQuote(address),
                          ",\"ready\":", reason.empty() ? "true" : "false",
                          ",\"reason\":", JsonQuote(reason), "}");
    };
    const RecentSearches::Summary s = searches_->Summarize(Clock::now());
    std::string out = absl::StrCat(
        "{\"extractor\":",
        service(backends_->options().extractor, extractor_reason),
        ",\"indexer\":", service(backends_->options().indexer, indexer_reason),
        ",\"stats\":", stats.ok() ? ToJson(*stats) : "null");
    if (!stats.ok())
      absl::StrAppend(&out, ",\"statsError\":", ErrorJson(stats.status(), ""));
    absl::StrAppend(
        &out, ",\"searches\":{\"total\":", s.total,
        ",\"inWindow\":", s.in_window, ",\"windowSeconds\":", s.window_s,
        ",\"perSecond\":", s.per_second, ",\"p50Ms\":", s.total_p50_ms,
        ",\"p95Ms\":", s.total_p95_ms, ",\"indexerP50Ms\":", s.indexer_p50_ms,
        ",\"indexerP95Ms\":", s.indexer_p95_ms, "}}");
    return JsonReply(std::move(out));
  }

  Reply Thumbnail(const httplib::Request& request, const CallMeta& meta) {
    absl::StatusOr<std::string> png =
        backends_->Thumbnail(request.matches[1].str(), meta);
    if (!png.ok()) return ErrorReply(png.status(), meta.request_id);
    return BytesReply(*std::move(png), "image/png");
  }

  Reply Preview(const httplib::Request& request, const CallMeta& meta) {
    absl::StatusOr<std::string> ply =
        backends_->Preview(request.matches[1].str(), meta);
    if (!ply.ok()) return ErrorReply(ply.status(), meta.request_id);
    return BytesReply(*std::move(ply), "application/octet-stream");
  }

 private:
  Reply RunSearch(const v1::SearchRequest& search, const CallMeta& meta,
                  Clock::time_point start, const std::string& query_json) {
    absl::StatusOr<SearchResult> result = backends_->Search(search, meta);
    if (!result.ok()) return ErrorReply(result.status(), meta.request_id);
    std::string out = "{";
    if (!query_json.empty())
      absl::StrAppend(&out, "\"query\":", query_json, ",");
    absl::StrAppend(&out, NeighborsJson(*result), "}");
    const Clock::time_point end = Clock::now();
    searches_->Add(
        end, std::chrono::duration<double, std::milli>(end - start).count(),
        result->stats.milliseconds());
    return JsonReply(std::move(out));
  }

  const Backends* backends_;
  RecentSearches* searches_;
  const ApiOptions options_;
};

}  // namespace

Reply ErrorReply(const absl::Status& status, const std::string& request_id) {
  Reply reply;
  reply.status = status;
  reply.http_status = HttpStatusOf(status.code());
  reply.body = ErrorJson(status, request_id);
  return reply;
}

std::vector<Route> ApiRoutes(const Backends* backends, RecentSearches* searches,
                             const ApiOptions& options) {
  auto handlers = std::make_shared<Handlers>(backends, searches, options);
  using Method = Reply (Handlers::*)(const httplib::Request&, const CallMeta&);
  auto bind = [handlers](Method method) {
    return [handlers, method](const httplib::Request& request,
                              const CallMeta& meta) {
      return ((*handlers).*method)(request, meta);
    };
  };
  const std::string id = "(.+)";
  return {
      {"GET", "/api/v1/search", "GET /api/v1/search", "/tpr.v1.Indexer/Search",
       bind(&Handlers::SearchById)},
      {"POST", "/api/v1/search", "POST /api/v1/search",
       "/tpr.v1.Extractor/Extract", bind(&Handlers::SearchPost)},
      {"GET", "/api/v1/models", "GET /api/v1/models", "/tpr.v1.Indexer/List",
       bind(&Handlers::ListModels)},
      {"POST", "/api/v1/models", "POST /api/v1/models",
       "/tpr.v1.Indexer/Upsert", bind(&Handlers::AddModel)},
      {"GET", "/api/v1/models/" + id, "GET /api/v1/models/{id}",
       "/tpr.v1.Indexer/Get", bind(&Handlers::GetModel)},
      {"DELETE", "/api/v1/models/" + id, "DELETE /api/v1/models/{id}",
       "/tpr.v1.Indexer/Delete", bind(&Handlers::DeleteModel)},
      {"GET", "/api/v1/stats", "GET /api/v1/stats", "/tpr.v1.Indexer/Stats",
       bind(&Handlers::Stats)},
      {"GET", "/api/v1/status", "GET /api/v1/status", "/tpr.v1.Indexer/Stats",
       bind(&Handlers::Status)},
      {"GET", "/api/v1/thumbnails/" + id, "GET /api/v1/thumbnails/{id}",
       "/tpr.v1.Indexer/GetThumbnail", bind(&Handlers::Thumbnail)},
      {"GET", "/api/v1/previews/" + id, "GET /api/v1/previews/{id}",
       "/tpr.v1.Indexer/GetPreview", bind(&Handlers::Preview)},
  };
}

}  // namespace tpr::web
