// The connection half of the SDK: channels over plaintext or TLS, the API
// key on every call, and a client interceptor that reports each call's
// request id and explains connection failures.
#include "tpr/connection.h"

#include <grpc/grpc.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>
#include <grpcpp/support/client_interceptor.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"

namespace tpr::client {
namespace {

using grpc::experimental::InterceptionHookPoints;

absl::StatusOr<std::string> ReadPem(const std::string& path,
                                    absl::string_view what) {
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return absl::NotFoundError(
        absl::StrCat("cannot read the ", what, " file ", path));
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// Adds the key, reads the request id, and turns a bare UNAVAILABLE or
// UNIMPLEMENTED into one that names the server and what is likely wrong.
class CallInterceptor final : public grpc::experimental::Interceptor {
 public:
  CallInterceptor(grpc::experimental::ClientRpcInfo* info,
                  std::shared_ptr<const ConnectionOptions> connection,
                  std::shared_ptr<const std::string> addresses)
      : method_(info->method() != nullptr ? info->method() : ""),
        connection_(std::move(connection)),
        addresses_(std::move(addresses)) {}

  void Intercept(
      grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(
            InterceptionHookPoints::PRE_SEND_INITIAL_METADATA) &&
        !connection_->api_key.empty()) {
      methods->GetSendInitialMetadata()->emplace(
          "authorization", "Bearer " + connection_->api_key);
    }
    if (methods->QueryInterceptionHookPoint(
            InterceptionHookPoints::POST_RECV_STATUS)) {
      grpc::Status* status = methods->GetRecvStatus();
      std::string request_id;
      if (auto* trailing = methods->GetRecvTrailingMetadata()) {
        auto it = trailing->find("x-request-id");
        if (it != trailing->end())
          request_id.assign(it->second.data(), it->second.size());
      }
      if (status->error_code() == grpc::StatusCode::UNAVAILABLE &&
          request_id.empty()) {
        *status = grpc::Status(
            status->error_code(),
            absl::StrCat("cannot reach ", Service(), " at ", *addresses_, ": ",
                         status->error_message(), Hint()),
            status->error_details());
      } else if (status->error_code() == grpc::StatusCode::UNIMPLEMENTED &&
                 status->error_message().empty()) {
        *status = grpc::Status(
            status->error_code(),
            absl::StrCat("the server at ", *addresses_, " does not serve ",
                         method_, ": it is not a ", Service(),
                         " (another service listens on that address?)"),
            status->error_details());
      }
      if (connection_->on_call_done)
        connection_->on_call_done(method_, request_id, *status);
    }
    methods->Proceed();
  }

 private:
  // The program that serves method_: "tpr-indexer" for
  // "/tpr.v1.Indexer/Search".
  std::string Service() const {
    if (absl::StartsWith(method_, "/tpr.v1.Extractor/")) return "tpr-extractor";
    if (absl::StartsWith(method_, "/tpr.v1.Indexer")) return "tpr-indexer";
    return "the server";
  }

  std::string Hint() const {
    if (!connection_->tls) {
      return " (no answer over plaintext: is the server down, or does it use "
             "TLS?)";
    }
    return " (TLS: is the server down, or was the handshake refused? check "
           "that the CA certificate is the authority that signed the "
           "server's certificate, that the address or the expected server "
           "name matches its name, that the server speaks TLS, and for "
           "mutual TLS that a client certificate and key are given)";
  }

  std::string method_;
  std::shared_ptr<const ConnectionOptions> connection_;
  std::shared_ptr<const std::string> addresses_;
};

class CallInterceptorFactory final
    : public grpc::experimental::ClientInterceptorFactoryInterface {
 public:
  CallInterceptorFactory(std::shared_ptr<const ConnectionOptions> connection,
                         std::shared_ptr<const std::string> addresses)
      : connection_(std::move(connection)), addresses_(std::move(addresses)) {}
  grpc::experimental::Interceptor* CreateClientInterceptor(
      grpc::experimental::ClientRpcInfo* info) override {
    return new CallInterceptor(info, connection_, addresses_);
  }

 private:
  std::shared_ptr<const ConnectionOptions> connection_;
  std::shared_ptr<const std::string> addresses_;
};

// Whether `host` is a dotted IPv4 literal (four decimal groups).
bool IsIpv4Literal(absl::string_view host) {
  std::vector<absl::string_view> parts = absl::StrSplit(host, '.');
  if (parts.size() != 4) return false;
  for (absl::string_view p : parts) {
    if (p.empty() || p.size() > 3) return false;
    for (char c : p) {
      if (!absl::ascii_isdigit(static_cast<unsigned char>(c))) return false;
    }
  }
  return true;
}

enum class Family { kIpv4, kIpv6, kName };

absl::StatusOr<Family> ClassifyAddress(absl::string_view address) {
  if (absl::StartsWith(address, "[")) {
    const size_t close = address.find(']');
    if (close == absl::string_view::npos || close + 1 >= address.size() ||
        address[close + 1] != ':' || close + 2 >= address.size()) {
      return absl::InvalidArgumentError(
          absl::StrCat("address '", address, "' needs the form [v6]:PORT"));
    }
    return Family::kIpv6;
  }
  const size_t colon = address.rfind(':');
  if (colon == absl::string_view::npos || colon == 0 ||
      colon + 1 == address.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("address '", address, "' needs the form HOST:PORT"));
  }
  return IsIpv4Literal(address.substr(0, colon)) ? Family::kIpv4
                                                 : Family::kName;
}

}  // namespace

absl::StatusOr<std::string> ChannelTarget(absl::string_view addresses) {
  addresses = absl::StripAsciiWhitespace(addresses);
  if (addresses.empty())
    return absl::InvalidArgumentError("no server address given");
  // Already a gRPC target with a resolver scheme.
  for (absl::string_view scheme :
       {"dns:", "ipv4:", "ipv6:", "unix:", "unix-abstract:"}) {
    if (absl::StartsWith(addresses, scheme)) return std::string(addresses);
  }
  std::vector<std::string> list;
  for (absl::string_view a :
       absl::StrSplit(addresses, ',', absl::SkipWhitespace())) {
    list.emplace_back(absl::StripAsciiWhitespace(a));
  }
  if (list.empty())
    return absl::InvalidArgumentError("no server address given");
  std::vector<Family> families;
  for (const std::string& a : list) {
    absl::StatusOr<Family> f = ClassifyAddress(a);
    if (!f.ok()) return f.status();
    families.push_back(*f);
  }
  if (std::any_of(families.begin(), families.end(),
                  [&](Family f) { return f != families.front(); })) {
    return absl::InvalidArgumentError(
        absl::StrCat("addresses '", addresses,
                     "' mix IPv4, IPv6 and host names; list one kind"));
  }
  switch (families.front()) {
    case Family::kIpv4:
      return absl::StrCat("ipv4:", absl::StrJoin(list, ","));
    case Family::kIpv6:
      return absl::StrCat("ipv6:", absl::StrJoin(list, ","));
    case Family::kName:
      if (list.size() > 1) {
        return absl::InvalidArgumentError(
            absl::StrCat("addresses '", addresses,
                         "' list several host names; give IP literals or one "
                         "dns:///NAME:PORT"));
      }
      return absl::StrCat("dns:///", list.front());
  }
  return absl::InternalError("unreachable");
}

absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(
    absl::string_view addresses) {
  return MakeChannel(addresses, ConnectionOptions());
}

ConnectionOptions ConnectionOptionsFromEnvironment() {
  ConnectionOptions connection;
  if (const char* key = std::getenv("TPR_API_KEY")) connection.api_key = key;
  return connection;
}

absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>>
MakeChannelCredentials(const ConnectionOptions& connection,
                       grpc::ChannelArguments* args) {
  std::shared_ptr<grpc::ChannelCredentials> credentials =
      grpc::InsecureChannelCredentials();
  if (connection.tls) {
    grpc::SslCredentialsOptions ssl;
    if (!connection.tls_ca_file.empty()) {
      absl::StatusOr<std::string> ca =
          ReadPem(connection.tls_ca_file, "CA certificate");
      if (!ca.ok()) return ca.status();
      ssl.pem_root_certs = *std::move(ca);
    }
    if (connection.tls_cert_file.empty() != connection.tls_key_file.empty()) {
      return absl::InvalidArgumentError(
          "a client certificate needs its key and a key its certificate");
    }
    if (!connection.tls_cert_file.empty()) {
      absl::StatusOr<std::string> cert =
          ReadPem(connection.tls_cert_file, "client certificate");
      if (!cert.ok()) return cert.status();
      absl::StatusOr<std::string> key =
          ReadPem(connection.tls_key_file, "client key");
      if (!key.ok()) return key.status();
      ssl.pem_cert_chain = *std::move(cert);
      ssl.pem_private_key = *std::move(key);
    }
    credentials = grpc::SslCredentials(ssl);
    if (!connection.tls_server_name.empty()) {
      args->SetSslTargetNameOverride(connection.tls_server_name);
    }
  } else if (!connection.tls_ca_file.empty() ||
             !connection.tls_cert_file.empty()) {
    return absl::InvalidArgumentError("TLS files given without TLS");
  }
  return credentials;
}

absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(
    absl::string_view addresses, const ConnectionOptions& connection) {
  absl::StatusOr<std::string> target = ChannelTarget(addresses);
  if (!target.ok()) return target.status();
  grpc::ChannelArguments args;
  args.SetLoadBalancingPolicyName("round_robin");
  args.SetMaxReceiveMessageSize(64 << 20);
  args.SetMaxSendMessageSize(64 << 20);
  // gRPC's reconnect backoff starts at 1 s and grows to 120 s; while a
  // subchannel waits, calls fail fast with UNAVAILABLE, so our retries would
  // all land inside one wait. Reconnecting on the scale of our own backoff
  // lets a restarted server be found within a retry or two.
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);

  absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> credentials =
      MakeChannelCredentials(connection, &args);
  if (!credentials.ok()) return credentials.status();
  std::vector<
      std::unique_ptr<grpc::experimental::ClientInterceptorFactoryInterface>>
      factories;
  factories.push_back(std::make_unique<CallInterceptorFactory>(
      std::make_shared<const ConnectionOptions>(connection),
      std::make_shared<const std::string>(
          absl::StripAsciiWhitespace(addresses))));
  return grpc::experimental::CreateCustomChannelWithInterceptors(
      *target, *credentials, args, std::move(factories));
}

}  // namespace tpr::client
