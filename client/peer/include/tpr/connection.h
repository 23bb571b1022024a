// How a TPR Search client reaches a server: the gRPC target of an address
// list, channels over plaintext or TLS that carry the API key on every call
// and explain connection failures, and the credentials for programs that
// build their own channels. Part of the SDK (tpr/client.h includes it) and
// shared with the servers that are clients of other servers (tpr-gateway to
// its shards, a follower tpr-indexer to its primary, tpr-web), which link
// this piece alone (tpr_peer), not the SDK.
//
//   tpr::client::ConnectionOptions connection;  connection.tls = true;
//   absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
//       tpr::client::MakeChannel("search.example.com:7002", connection);
#ifndef TPR_CLIENT_CONNECTION_H_
#define TPR_CLIENT_CONNECTION_H_

#include <grpcpp/channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>
#include <grpcpp/support/status.h>

#include <cstddef>
#include <functional>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace tpr::client {

// ChannelTarget returns the gRPC target for `addresses`:
//   "127.0.0.1:7001"                   -> "ipv4:127.0.0.1:7001"
//   "127.0.0.1:7001,127.0.0.1:7002"    -> "ipv4:127.0.0.1:7001,127.0.0.1:7002"
//   "[::1]:7001,[::1]:7002"            -> "ipv6:[::1]:7001,[::1]:7002"
//   "localhost:7001"                   -> "dns:///localhost:7001"
//   "dns:///name:7001", "ipv4:...", "unix:/path" -> unchanged.
// Errors: INVALID_ARGUMENT for an empty list, an entry without a port, a
// list mixing families, or several host names (use one dns:/// name that
// resolves to several addresses instead). O(length). Thread-safe.
absl::StatusOr<std::string> ChannelTarget(absl::string_view addresses);

// MakeChannel returns an insecure channel to ChannelTarget(addresses) with
// round_robin load balancing (every resolved address gets calls in turn)
// and 64 MiB message limits, reconnecting after a failure within 100 ms to
// 2 s (gRPC's default starts at 1 s and grows to 120 s). Connection happens
// lazily on the first call.
// Errors: those of ChannelTarget.
absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(
    absl::string_view addresses);

// ConnectionOptions: how a client reaches and authenticates to the servers
// (TLS, API key) and what it hears about each call. Defaults: plaintext, no
// key.
struct ConnectionOptions {
  // Speak TLS. Default false.
  bool tls = false;
  // PEM file of the certificate authorities to trust; empty: the system's
  // roots. Only with tls.
  std::string tls_ca_file;
  // PEM client certificate chain and private key, for servers that demand
  // mutual TLS (--tls-client-ca). Both or neither. Only with tls.
  std::string tls_cert_file;
  std::string tls_key_file;
  // Name the server's certificate must carry when it differs from the host
  // in the address (e.g. connecting by IP). Empty: the address's host.
  std::string tls_server_name;
  // API key, sent with every call as `authorization: Bearer <key>`. Empty:
  // none. ConnectionOptionsFromEnvironment() reads TPR_API_KEY.
  std::string api_key;
  // Called when each call ends (on the thread that ends it) with the full
  // method name, the server's request id (trailing `x-request-id`, "" when
  // the call never reached a server) and the final status. Default none.
  std::function<void(absl::string_view method, absl::string_view request_id,
                     const grpc::Status& status)>
      on_call_done;
};

// ConnectionOptionsFromEnvironment returns default options with api_key
// taken from the TPR_API_KEY environment variable (empty when unset).
ConnectionOptions ConnectionOptionsFromEnvironment();

// MakeChannel with `connection`: as above, over TLS when connection.tls (the
// files are read now: NOT_FOUND naming a missing one, INVALID_ARGUMENT for
// a certificate without its key), adding the API key to every call. A call
// that cannot connect fails with UNAVAILABLE and a hint: plaintext against
// a TLS server, or a TLS handshake refused (wrong CA, wrong name, missing
// client certificate), never a hang.
absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(
    absl::string_view addresses, const ConnectionOptions& connection);

// MakeChannelCredentials returns the channel credentials MakeChannel uses
// for `connection` (plaintext, or TLS with the CA and client certificate
// files read now) and sets the TLS server-name override in `*args`; the API
// key is not in them (MakeChannel adds it per call). For programs that build
// their own channels, e.g. tpr-gateway's to its shards. Errors: NOT_FOUND
// naming a missing file, INVALID_ARGUMENT for a certificate without its key
// or TLS files without tls. Thread-safe.
absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>>
MakeChannelCredentials(const ConnectionOptions& connection,
                       grpc::ChannelArguments* args);

// kChunkBytes is the size of one upload message of ExtractorClient: 1 MiB,
// well under gRPC's 4 MiB default message limit.
inline constexpr size_t kChunkBytes = size_t{1} << 20;

}  // namespace tpr::client

#endif  // TPR_CLIENT_CONNECTION_H_
