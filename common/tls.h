// TLS for the TPR servers: certificate and key files reloaded when they
// change (gRPC's FileWatcherCertificateProvider: the files are re-read every
// refresh interval, so a renewed certificate is served without a restart),
// and optional mutual TLS (--tls-client-ca: clients must present a
// certificate signed by that authority).
//
//   tpr::common::TlsServerOptions tls;
//   tls.cert_file = "server.pem";  tls.key_file = "server.key";
//   absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> creds =
//       tpr::common::MakeTlsServerCredentials(tls);
//   server_options.credentials = *creds;   // API keys attach to it
#ifndef TPR_COMMON_TLS_H_
#define TPR_COMMON_TLS_H_

#include <grpcpp/security/server_credentials.h>

#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tpr::common {

// TlsServerOptions: the files of the server's identity.
struct TlsServerOptions {
  // PEM certificate chain and private key. Both required.
  std::string cert_file;
  std::string key_file;
  // PEM authority whose signature a client certificate must carry; empty:
  // clients are not asked for a certificate. Default empty.
  std::string client_ca_file;
  // How often the files are checked for changes, in seconds. Default 10.
  int refresh_interval_s = 10;
};

// CheckTlsFiles reads the files now and checks that they hold a PEM
// certificate, a PEM private key that matches it, and (when given) a PEM
// client CA, using OpenSSL. Returns NOT_FOUND or INVALID_ARGUMENT naming
// the file at fault (gRPC's watcher would otherwise only log, and every
// handshake would fail). Thread-safe.
absl::Status CheckTlsFiles(const TlsServerOptions& options);

// MakeTlsServerCredentials checks the files (CheckTlsFiles) and returns TLS
// server credentials over a FileWatcherCertificateProvider. Errors: those of
// CheckTlsFiles.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>>
MakeTlsServerCredentials(const TlsServerOptions& options);

}  // namespace tpr::common

#endif  // TPR_COMMON_TLS_H_
