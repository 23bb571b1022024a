// The connection half of the SDK: channels over plaintext or TLS, the API
// key on every call, and a client interceptor that reports each call's
// request id and explains connection failures.
#include <grpc/grpc.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>
#include <grpcpp/support/client_interceptor.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "tpr/client.h"

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

// Adds the key, reads the request id, and turns a bare UNAVAILABLE into one
// that says what is likely wrong.
class CallInterceptor final : public grpc::experimental::Interceptor {
 public:
  CallInterceptor(grpc::experimental::ClientRpcInfo* info,
                  std::shared_ptr<const ConnectionOptions> connection)
      : method_(info->method() != nullptr ? info->method() : ""),
        connection_(std::move(connection)) {}

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
        *status = grpc::Status(status->error_code(),
                               absl::StrCat(status->error_message(), Hint()),
                               status->error_details());
      }
      if (connection_->on_call_done)
        connection_->on_call_done(method_, request_id, *status);
    }
    methods->Proceed();
  }

 private:
  std::string Hint() const {
    if (!connection_->tls) {
      return " (no answer over plaintext: is the server down, or does it use "
             "TLS? then "
             "connect with --tls / ConnectionOptions::tls)";
    }
    return " (TLS: is the server down, or was the handshake refused? check "
           "that --tls-ca is "
           "the authority that signed the server's certificate, that the "
           "address or "
           "--tls-server-name matches its name, that the server speaks TLS, "
           "and for mutual "
           "TLS give --tls-cert and --tls-key)";
  }

  std::string method_;
  std::shared_ptr<const ConnectionOptions> connection_;
};

class CallInterceptorFactory final
    : public grpc::experimental::ClientInterceptorFactoryInterface {
 public:
  explicit CallInterceptorFactory(
      std::shared_ptr<const ConnectionOptions> connection)
      : connection_(std::move(connection)) {}
  grpc::experimental::Interceptor* CreateClientInterceptor(
      grpc::experimental::ClientRpcInfo* info) override {
    return new CallInterceptor(info, connection_);
  }

 private:
  std::shared_ptr<const ConnectionOptions> connection_;
};

}  // namespace

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
          "a client certificate needs its key and a key its certificate "
          "(--tls-cert with "
          "--tls-key)");
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
    return absl::InvalidArgumentError(
        "TLS files given without TLS (add --tls)");
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
      std::make_shared<const ConnectionOptions>(connection)));
  return grpc::experimental::CreateCustomChannelWithInterceptors(
      *target, *credentials, args, std::move(factories));
}

absl::StatusOr<ExtractorClient> ExtractorClient::Connect(
    absl::string_view addresses, const ConnectionOptions& connection,
    CallOptions defaults) {
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
      MakeChannel(addresses, connection);
  if (!channel.ok()) return channel.status();
  return ExtractorClient(*std::move(channel), defaults);
}

absl::StatusOr<IndexerClient> IndexerClient::Connect(
    absl::string_view addresses, const ConnectionOptions& connection,
    CallOptions defaults) {
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
      MakeChannel(addresses, connection);
  if (!channel.ok()) return channel.status();
  return IndexerClient(*std::move(channel), defaults);
}

}  // namespace tpr::client
