#include "common/auth.h"

#include <google/protobuf/descriptor.h>
#include <grpc/grpc.h>
#include <grpc/grpc_security.h>
#include <grpc/slice.h>
#include <openssl/rand.h>
#include <openssl/sha.h>
#include <sys/stat.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "common/logging.h"
#include "tpr/v1/access.pb.h"

namespace tpr::common {
namespace {

constexpr absl::string_view kHashPrefix = "sha256:";
constexpr absl::string_view kKeyPrefix = "tpr_";

std::string Hex(const unsigned char* bytes, size_t n) {
  std::string out;
  out.reserve(2 * n);
  for (size_t i = 0; i < n; ++i) absl::StrAppendFormat(&out, "%02x", bytes[i]);
  return out;
}

bool IsLowerHex(absl::string_view s) {
  for (char c : s) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  }
  return true;
}

// The grpc::AuthMetadataProcessor over an authenticator. Non-blocking: gRPC
// runs it inline in the auth filter (no thread hop per call).
class KeyProcessor final : public grpc::AuthMetadataProcessor {
 public:
  explicit KeyProcessor(const ApiKeyAuthenticator* auth) : auth_(auth) {}
  bool IsBlocking() const override { return false; }

  grpc::Status Process(const InputMetadata& md, grpc::AuthContext* /*context*/,
                       OutputMetadata* consumed,
                       OutputMetadata* /*response*/) override {
    absl::string_view method;
    absl::string_view authorization;
    if (auto it = md.find(":path"); it != md.end()) {
      method = absl::string_view(it->second.data(), it->second.size());
    }
    if (auto it = md.find("authorization"); it != md.end()) {
      authorization = absl::string_view(it->second.data(), it->second.size());
      consumed->emplace("authorization", std::string(authorization));
    }
    const absl::Status status = auth_->Check(method, authorization);
    if (status.ok()) return grpc::Status::OK;
    return grpc::Status(static_cast<grpc::StatusCode>(status.code()),
                        std::string(status.message()));
  }

 private:
  const ApiKeyAuthenticator* auth_;
};

// Plaintext credentials that accept a processor: the core's insecure
// credentials (which, unlike grpc::InsecureServerCredentials(), run the auth
// filter) with a C trampoline into the C++ processor.
class InsecureWithAuth final : public grpc::ServerCredentials {
 public:
  explicit InsecureWithAuth(
      std::shared_ptr<grpc::AuthMetadataProcessor> processor)
      : processor_(std::move(processor)) {}

  void SetAuthMetadataProcessor(
      const std::shared_ptr<grpc::AuthMetadataProcessor>& processor) override {
    processor_ = processor;
  }

 private:
  int AddPortToServer(const std::string& addr, grpc_server* server) override {
    grpc_server_credentials* creds = grpc_insecure_server_credentials_create();
    grpc_auth_metadata_processor c_processor;
    c_processor.process = &InsecureWithAuth::ProcessC;
    c_processor.destroy = nullptr;
    c_processor.state = processor_.get();  // Kept alive by this object.
    grpc_server_credentials_set_auth_metadata_processor(creds, c_processor);
    const int port = grpc_server_add_http2_port(server, addr.c_str(), creds);
    grpc_server_credentials_release(creds);
    return port;
  }

  static void ProcessC(void* state, grpc_auth_context* /*context*/,
                       const grpc_metadata* md, size_t num_md,
                       grpc_process_auth_metadata_done_cb cb, void* user_data) {
    auto* processor = static_cast<grpc::AuthMetadataProcessor*>(state);
    grpc::AuthMetadataProcessor::InputMetadata input;
    for (size_t i = 0; i < num_md; ++i) {
      input.emplace(
          grpc::string_ref(
              reinterpret_cast<const char*>(GRPC_SLICE_START_PTR(md[i].key)),
              GRPC_SLICE_LENGTH(md[i].key)),
          grpc::string_ref(
              reinterpret_cast<const char*>(GRPC_SLICE_START_PTR(md[i].value)),
              GRPC_SLICE_LENGTH(md[i].value)));
    }
    grpc::AuthMetadataProcessor::OutputMetadata consumed;
    grpc::AuthMetadataProcessor::OutputMetadata response;
    const grpc::Status status =
        processor->Process(input, nullptr, &consumed, &response);
    if (!status.ok()) {
      cb(user_data, nullptr, 0, nullptr, 0,
         static_cast<grpc_status_code>(status.error_code()),
         status.error_message().c_str());
      return;
    }
    std::vector<grpc_metadata> consumed_md;
    for (size_t i = 0; i < num_md; ++i) {
      const absl::string_view key(
          reinterpret_cast<const char*>(GRPC_SLICE_START_PTR(md[i].key)),
          GRPC_SLICE_LENGTH(md[i].key));
      if (consumed.count(std::string(key)) > 0) consumed_md.push_back(md[i]);
    }
    cb(user_data, consumed_md.data(), consumed_md.size(), nullptr, 0,
       GRPC_STATUS_OK, nullptr);
  }

  std::shared_ptr<grpc::AuthMetadataProcessor> processor_;
};

}  // namespace

absl::StatusOr<Role> ParseRole(absl::string_view name) {
  if (name == "read") return Role::kRead;
  if (name == "write") return Role::kWrite;
  if (name == "admin") return Role::kAdmin;
  return absl::InvalidArgumentError(absl::StrCat(
      "unknown role '", name, "' (expected read, write or admin)"));
}

absl::string_view RoleName(Role role) {
  switch (role) {
    case Role::kRead:
      return "read";
    case Role::kWrite:
      return "write";
    case Role::kAdmin:
      return "admin";
    case Role::kNone:
      break;
  }
  return "none";
}

Role RequiredRole(absl::string_view method) {
  if (absl::StartsWith(method, "/grpc.health.v1.Health/") ||
      absl::StartsWith(method, "/grpc.reflection.")) {
    return Role::kNone;
  }
  // "/pkg.Service/Method" -> "pkg.Service.Method", as the descriptor pool
  // names it; anything else is no method and needs admin.
  const size_t slash = method.rfind('/');
  if (method.size() < 2 || method[0] != '/' || slash == 0 ||
      slash == absl::string_view::npos) {
    return Role::kAdmin;
  }
  const std::string full_name =
      absl::StrCat(method.substr(1, slash - 1), ".", method.substr(slash + 1));
  const google::protobuf::MethodDescriptor* descriptor =
      google::protobuf::DescriptorPool::generated_pool()->FindMethodByName(
          full_name);
  if (descriptor == nullptr) return Role::kAdmin;
  switch (descriptor->options().GetExtension(tpr::v1::required_role)) {
    case tpr::v1::ACCESS_ROLE_READ:
      return Role::kRead;
    case tpr::v1::ACCESS_ROLE_WRITE:
      return Role::kWrite;
    default:
      return Role::kAdmin;
  }
}

absl::StatusOr<std::string> NewApiKey() {
  unsigned char bytes[32];
  if (RAND_bytes(bytes, sizeof(bytes)) != 1) {
    return absl::InternalError("OpenSSL RAND_bytes failed");
  }
  return absl::StrCat(kKeyPrefix, Hex(bytes, sizeof(bytes)));
}

std::string HashApiKey(absl::string_view key) {
  unsigned char digest[SHA256_DIGEST_LENGTH];
  SHA256(reinterpret_cast<const unsigned char*>(key.data()), key.size(),
         digest);
  return absl::StrCat(kHashPrefix, Hex(digest, sizeof(digest)));
}

std::string KeyFileLine(absl::string_view key, Role role,
                        absl::string_view name) {
  std::string line = absl::StrCat(HashApiKey(key), " ", RoleName(role));
  if (!name.empty()) absl::StrAppend(&line, " ", name);
  return line;
}

absl::StatusOr<KeyTable> ParseKeyFile(absl::string_view text) {
  KeyTable table;
  int line_number = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    line = absl::StripAsciiWhitespace(line);
    if (line.empty() || line[0] == '#') continue;
    std::vector<absl::string_view> fields =
        absl::StrSplit(line, absl::ByAnyChar(" \t"), absl::SkipEmpty());
    if (fields.size() < 2) {
      return absl::InvalidArgumentError(absl::StrCat(
          "line ", line_number, ": expected 'sha256:<hex> <role> [name]'"));
    }
    absl::string_view hash = fields[0];
    if (!absl::StartsWith(hash, kHashPrefix) ||
        hash.size() != kHashPrefix.size() + 64 ||
        !IsLowerHex(hash.substr(kHashPrefix.size()))) {
      return absl::InvalidArgumentError(absl::StrCat(
          "line ", line_number,
          ": the hash must be 'sha256:' and 64 lower-case hex digits"));
    }
    absl::StatusOr<Role> role = ParseRole(fields[1]);
    if (!role.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("line ", line_number, ": ", role.status().message()));
    }
    if (!table.emplace(std::string(hash), *role).second) {
      return absl::InvalidArgumentError(
          absl::StrCat("line ", line_number, ": duplicate key"));
    }
  }
  return table;
}

ApiKeyAuthenticator::ApiKeyAuthenticator(std::string path, std::string log_name)
    : path_(std::move(path)), log_name_(std::move(log_name)) {}

absl::StatusOr<std::shared_ptr<ApiKeyAuthenticator>> ApiKeyAuthenticator::Open(
    const std::string& path, std::string log_name, int watch_interval_ms) {
  std::shared_ptr<ApiKeyAuthenticator> auth(
      new ApiKeyAuthenticator(path, std::move(log_name)));
  if (absl::Status s = auth->Reload(); !s.ok()) return s;
  auth->processor_ = std::make_shared<KeyProcessor>(auth.get());
  if (watch_interval_ms > 0) {
    auth->watcher_ = std::thread([raw = auth.get(), watch_interval_ms] {
      raw->Watch(watch_interval_ms);
    });
  }
  return auth;
}

ApiKeyAuthenticator::~ApiKeyAuthenticator() {
  {
    std::lock_guard<std::mutex> lock(watch_mu_);
    stopping_ = true;
  }
  watch_cv_.notify_all();
  if (watcher_.joinable()) watcher_.join();
}

absl::Status ApiKeyAuthenticator::Reload() {
  struct stat info;
  if (stat(path_.c_str(), &info) != 0) {
    absl::Status s =
        absl::NotFoundError(absl::StrCat("cannot read keys file ", path_));
    if (keys_ != nullptr)
      LogWarning(log_name_,
                 absl::StrCat(s.message(), "; keeping the current keys"));
    return s;
  }
  std::ifstream in(path_, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  absl::StatusOr<KeyTable> table = ParseKeyFile(text.str());
  std::lock_guard<std::mutex> lock(mu_);
  mtime_ns_ = int64_t{info.st_mtim.tv_sec} * 1000000000 + info.st_mtim.tv_nsec;
  size_ = info.st_size;
  if (!table.ok()) {
    absl::Status s = absl::InvalidArgumentError(
        absl::StrCat("keys file ", path_, ": ", table.status().message()));
    if (keys_ != nullptr)
      LogWarning(log_name_,
                 absl::StrCat(s.message(), "; keeping the current keys"));
    return s;
  }
  const bool first = keys_ == nullptr;
  keys_ = std::make_shared<const KeyTable>(*std::move(table));
  LogEvent(log_name_, absl::StrCat(first ? "loaded " : "reloaded ",
                                   keys_->size(), " API keys from ", path_));
  return absl::OkStatus();
}

void ApiKeyAuthenticator::Watch(int interval_ms) {
  std::unique_lock<std::mutex> lock(watch_mu_);
  while (!watch_cv_.wait_for(lock, std::chrono::milliseconds(interval_ms),
                             [&] { return stopping_; })) {
    struct stat info;
    if (stat(path_.c_str(), &info) != 0) continue;
    const int64_t mtime =
        int64_t{info.st_mtim.tv_sec} * 1000000000 + info.st_mtim.tv_nsec;
    bool changed;
    {
      std::lock_guard<std::mutex> keys_lock(mu_);
      changed = mtime != mtime_ns_ || info.st_size != size_;
    }
    if (changed) (void)Reload();  // Errors are logged by Reload.
  }
}

absl::Status ApiKeyAuthenticator::Check(absl::string_view method,
                                        absl::string_view authorization) const {
  const Role needed = RequiredRole(method);
  if (needed == Role::kNone) return absl::OkStatus();
  auto refuse = [&](absl::Status status) {
    (status.code() == absl::StatusCode::kUnauthenticated ? unauthenticated_
                                                         : permission_denied_)
        .fetch_add(1, std::memory_order_relaxed);
    LogWarning(log_name_, absl::StrCat("rpc=", method, " refused: ",
                                       absl::StatusCodeToString(status.code()),
                                       " (", status.message(), ")"));
    if (on_refused_) on_refused_(std::string(method), status.code());
    return status;
  };
  if (authorization.empty()) {
    return refuse(absl::UnauthenticatedError(
        "this server requires an API key: send 'authorization: Bearer <key>' "
        "(tpr --api-key or TPR_API_KEY)"));
  }
  constexpr absl::string_view kBearer = "Bearer ";
  if (!absl::StartsWithIgnoreCase(authorization, kBearer)) {
    return refuse(absl::UnauthenticatedError(
        "malformed authorization header: expected 'Bearer <key>'"));
  }
  const std::string hash = HashApiKey(
      absl::StripAsciiWhitespace(authorization.substr(kBearer.size())));
  std::shared_ptr<const KeyTable> keys;
  {
    std::lock_guard<std::mutex> lock(mu_);
    keys = keys_;
  }
  auto it = keys->find(hash);
  if (it == keys->end())
    return refuse(absl::UnauthenticatedError("unknown API key"));
  if (it->second < needed) {
    return refuse(absl::PermissionDeniedError(
        absl::StrCat(method, " needs the ", RoleName(needed),
                     " role; this key has ", RoleName(it->second))));
  }
  return absl::OkStatus();
}

std::shared_ptr<grpc::AuthMetadataProcessor> ApiKeyAuthenticator::Processor() {
  return processor_;
}

std::shared_ptr<grpc::ServerCredentials> InsecureServerCredentialsWithAuth(
    std::shared_ptr<grpc::AuthMetadataProcessor> processor) {
  return std::make_shared<InsecureWithAuth>(std::move(processor));
}

}  // namespace tpr::common
