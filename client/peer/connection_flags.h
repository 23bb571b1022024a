// Command-line flags for a server that is itself a client of another
// server: tpr-gateway reaching its shards (--shard-tls...) and a follower
// tpr-indexer reaching its primary (--follow-tls...). One definition, so
// the two spell and explain them alike; the `tpr` command's own flags are
// client/cli/connection.cc (no prefix, with environment variables).
//
//   tpr::client::ConnectionOptions primary;
//   tpr::client::AddPeerConnectionFlags(app, "follow", "the primary",
//                                       &primary);
//   ... CLI11_PARSE ...; MakeChannelCredentials(primary, &args)
//
// Header-only and templated on the CLI11 app type, so that tpr_peer does not
// depend on CLI11. Not part of the installed SDK.
#ifndef TPR_CLIENT_PEER_CONNECTION_FLAGS_H_
#define TPR_CLIENT_PEER_CONNECTION_FLAGS_H_

#include <string>

#include "tpr/connection.h"

namespace tpr::client {

// AddPeerConnectionFlags adds --PREFIX-tls, --PREFIX-tls-ca,
// --PREFIX-tls-cert, --PREFIX-tls-key and --PREFIX-tls-server-name to `app`
// (a CLI::App), filling the TLS fields of `*connection`; `peer` names the
// server reached, for the help texts ("the shards"). The API key stays the
// caller's flag (its role and environment variable differ per program).
// `*connection` must outlive parsing.
template <typename App>
void AddPeerConnectionFlags(App& app, const std::string& prefix,
                            const std::string& peer,
                            ConnectionOptions* connection) {
  const std::string p = "--" + prefix + "-tls";
  app.add_flag(p, connection->tls, "speak TLS to " + peer);
  app.add_option(p + "-ca", connection->tls_ca_file,
                 "PEM authority the certificates of " + peer +
                     " are checked against (default: the system's roots)");
  app.add_option(p + "-cert", connection->tls_cert_file,
                 "PEM client certificate for " + peer +
                     " when it demands mutual TLS (with " + p + "-key)");
  app.add_option(p + "-key", connection->tls_key_file,
                 "PEM private key of " + p + "-cert");
  app.add_option(p + "-server-name", connection->tls_server_name,
                 "name the certificate of " + peer +
                     " carries, when not the host in its address");
}

}  // namespace tpr::client

#endif  // TPR_CLIENT_PEER_CONNECTION_FLAGS_H_
