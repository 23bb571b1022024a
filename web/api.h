// The HTTP/JSON API of tpr-web, /api/v1/...: each route turns one HTTP
// request into calls of the extractor and the indexer (Backends) and their
// answers into JSON, in the proto's own JSON mapping (protobuf's
// json_util: lowerCamelCase names, 64-bit integers as strings, bytes as
// base64), so the wire contract stays the one in proto/tpr/v1.
//
//   GET    /api/v1/search?id=ID&k=&radius=&label=&intent=&exclude_self=
//   POST   /api/v1/search      mesh upload (multipart field "mesh", or the
//                              raw file as the body with ?file_name=),
//                              k, radius, label, intent, explain, preview,
//                              thumbnail as query or form fields; or a
//                              tpr.v1.SearchRequest as JSON
//   GET    /api/v1/models?label=&page_size=&page_token=   tpr.v1.ListResponse
//   POST   /api/v1/models?id=&label=&overwrite=   upload, extract, store
//   GET    /api/v1/models/{id}                     tpr.v1.Model
//   DELETE /api/v1/models/{id}
//   GET    /api/v1/stats                           tpr.v1.StatsResponse
//   GET    /api/v1/status      readiness of both services, stats, searches
//   GET    /api/v1/thumbnails/{id}                 image/png
//   GET    /api/v1/previews/{id}                   binary PLY
// {id} is the model id URL-encoded (any allowed character, '/' included).
// Errors: web/http_errors.h.
#ifndef TPR_WEB_API_H_
#define TPR_WEB_API_H_

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "web/backends.h"
#include "web/http_errors.h"
#include "web/recent_searches.h"

namespace httplib {
struct Request;
}  // namespace httplib

namespace tpr::web {

// Reply: one HTTP answer of a route.
struct Reply {
  // OK, or the error the body reports (then http_status and the body come
  // from it: ErrorReply).
  absl::Status status;
  int http_status = 200;
  std::string content_type = kJsonType;
  std::string body;
  // Extra response headers.
  std::vector<std::pair<std::string, std::string>> headers;
};

// ErrorReply returns the JSON error reply of `status` (not OK).
Reply ErrorReply(const absl::Status& status, const std::string& request_id);

// Route: one method and path pattern of the API.
struct Route {
  // HTTP method: "GET", "POST", "DELETE".
  std::string method;
  // Path as a regular expression over the decoded path; groups are the
  // path parameters.
  std::string pattern;
  // Name in logs and metrics ("GET /api/v1/models/{id}"): never an id.
  std::string name;
  // The gRPC method whose role the route needs (common/auth.h RequiredRole),
  // e.g. "/tpr.v1.Indexer/Get".
  std::string grpc_method;
  std::function<Reply(const httplib::Request&, const CallMeta&)> handler;
};

// ApiOptions: limits of the API.
struct ApiOptions {
  // Largest k a search may ask for through the API (the indexer has its
  // own --max-k). Default 1000.
  int max_k = 1000;
  // k when the request gives none. Default 10.
  int default_k = 10;
};

// Routes returns every route of the API over `backends` and `searches`
// (both must outlive the routes). Handlers are thread-safe.
std::vector<Route> ApiRoutes(const Backends* backends, RecentSearches* searches,
                             const ApiOptions& options = {});

}  // namespace tpr::web

#endif  // TPR_WEB_API_H_
