// API keys and roles for the TPR services.
//
// Keys file (--api-keys FILE): one key per line, only its hash stored,
//
//   # comments and blank lines are ignored
//   sha256:4f1c...64 hex digits...  write  ingest-job
//
// i.e. "sha256:<hex of SHA-256(key)> <role> [name...]". `tpr key new --role
// ROLE --keys FILE` appends such a line and prints the key once. A key is
// "tpr_" followed by 64 hex digits (256 random bits from OpenSSL's RAND_bytes);
// with that much entropy a single unsalted SHA-256 is as strong as a slow
// password hash (nothing to brute-force), and it keeps the check to one
// hash per call.
//
// Roles nest: read < write < admin. Each method declares the role it needs
// in the contract (the tpr.v1.required_role option, proto/tpr/v1/access.proto),
// read here from the compiled-in descriptors; today
//   read:  Search, Get, List, Stats, GetThumbnail, GetPreview
//          (tpr.v1.Indexer),
//          Extract (tpr.v1.Extractor)
//   write: read + Upsert, BatchUpsert, Delete
//   admin: write + every method that declares no role (backup, restore, ...)
// Health checks (grpc.health.v1) and reflection stay open. Every other call
// needs `authorization: Bearer <key>` metadata: a missing, malformed or
// unknown key gets UNAUTHENTICATED, a key whose role is too low
// PERMISSION_DENIED. The check runs in gRPC's auth filter, before the
// handler, the call interceptor and its log line; the `authorization` header
// is consumed there, so handlers and logs never see it.
//
// Reload: the file is re-read on SIGHUP (common/server_lifecycle.h) and when
// its modification time or size changes (checked every second). A file that
// fails to parse on reload is reported and the previous keys stay in force.
#ifndef TPR_COMMON_AUTH_H_
#define TPR_COMMON_AUTH_H_

#include <grpcpp/security/auth_metadata_processor.h>
#include <grpcpp/security/server_credentials.h>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace tpr::common {

// Role: what a key may do; a higher role includes the lower ones.
enum class Role { kNone = 0, kRead = 1, kWrite = 2, kAdmin = 3 };

// ParseRole maps "read", "write", "admin" to a Role; INVALID_ARGUMENT
// otherwise. RoleName is the inverse ("none" for kNone).
absl::StatusOr<Role> ParseRole(absl::string_view name);
absl::string_view RoleName(Role role);

// RequiredRole returns the role a call of `method` ("/tpr.v1.Indexer/Search")
// needs: kNone for health checks and reflection (open), the method's
// tpr.v1.required_role option when it declares one, kAdmin for any other
// method (a method this binary does not know included). One descriptor
// lookup. Thread-safe.
Role RequiredRole(absl::string_view method);

// NewApiKey returns a fresh key, "tpr_" + 64 hex digits from RAND_bytes.
// INTERNAL when OpenSSL's generator fails. Thread-safe.
absl::StatusOr<std::string> NewApiKey();

// HashApiKey returns "sha256:" + the lower-case hex SHA-256 of `key`.
std::string HashApiKey(absl::string_view key);

// KeyFileLine returns the keys-file line for `key` ("sha256:... role name").
std::string KeyFileLine(absl::string_view key, Role role,
                        absl::string_view name);

// KeyTable: hash -> role, as read from a keys file.
using KeyTable = std::unordered_map<std::string, Role>;

// ParseKeyFile parses keys-file text. INVALID_ARGUMENT naming the line at
// fault (bad hash, unknown role, duplicate hash). An empty file is valid
// (and locks everything but health and reflection).
absl::StatusOr<KeyTable> ParseKeyFile(absl::string_view text);

// ApiKeyAuthenticator: the keys of one file, reloadable, and the check of
// one call. Thread-safe.
class ApiKeyAuthenticator {
 public:
  // Open reads `path` (NOT_FOUND / INVALID_ARGUMENT with the path and line)
  // and, when watch_interval_ms > 0, starts a thread that reloads the file
  // when it changes. `log_name` prefixes the reload log lines.
  static absl::StatusOr<std::shared_ptr<ApiKeyAuthenticator>> Open(
      const std::string& path, std::string log_name,
      int watch_interval_ms = 1000);
  ~ApiKeyAuthenticator();

  // Reload re-reads the file; on error the current keys stay and the error
  // is returned (and logged). Thread-safe.
  absl::Status Reload();

  // Check decides a call of `method` carrying `authorization` (the header's
  // value, "" when absent). Returns OK, UNAUTHENTICATED or PERMISSION_DENIED
  // (messages never contain the key). Cost: one SHA-256 and one hash-map
  // lookup, about a microsecond. Thread-safe.
  absl::Status Check(absl::string_view method,
                     absl::string_view authorization) const;

  // Calls refused so far (UNAUTHENTICATED, PERMISSION_DENIED).
  uint64_t unauthenticated() const { return unauthenticated_.load(); }
  uint64_t permission_denied() const { return permission_denied_.load(); }

  // SetRefusalObserver makes every refusal of Check call `observer` with
  // the method and the code (metrics count them; the log line is Check's
  // own). Call before the server starts. Default none.
  void SetRefusalObserver(
      std::function<void(const std::string& method, absl::StatusCode code)>
          observer) {
    on_refused_ = std::move(observer);
  }

  // Processor returns the gRPC auth-metadata processor running Check
  // (non-blocking: it runs inline in the auth filter). It consumes the
  // authorization header.
  std::shared_ptr<grpc::AuthMetadataProcessor> Processor();

 private:
  ApiKeyAuthenticator(std::string path, std::string log_name);
  void Watch(int interval_ms);

  const std::string path_;
  const std::string log_name_;
  mutable std::mutex mu_;
  std::shared_ptr<const KeyTable> keys_;  // Guarded by mu_.
  int64_t mtime_ns_ = 0;                  // Guarded by mu_.
  int64_t size_ = -1;                     // Guarded by mu_.
  mutable std::atomic<uint64_t> unauthenticated_{0};
  mutable std::atomic<uint64_t> permission_denied_{0};
  std::function<void(const std::string&, absl::StatusCode)> on_refused_;
  std::mutex watch_mu_;
  std::condition_variable watch_cv_;
  bool stopping_ = false;
  std::thread watcher_;
  std::shared_ptr<grpc::AuthMetadataProcessor> processor_;
};

// InsecureServerCredentialsWithAuth returns plaintext server credentials
// whose calls pass `processor` (grpc::InsecureServerCredentials() refuses
// processors). Keys then travel in clear text: use TLS (common/tls.h) off
// loopback.
std::shared_ptr<grpc::ServerCredentials> InsecureServerCredentialsWithAuth(
    std::shared_ptr<grpc::AuthMetadataProcessor> processor);

}  // namespace tpr::common

#endif  // TPR_COMMON_AUTH_H_
