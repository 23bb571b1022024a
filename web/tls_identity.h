// TlsIdentity: the certificate and key tpr-web serves HTTPS with, read
// from the services' TLS flags (common/tls.h: --tls-cert, --tls-key,
// --tls-client-ca, --tls-refresh-s) and re-read when the files change, as
// the gRPC services do: a renewed certificate is served without a restart.
//
//   absl::StatusOr<std::shared_ptr<TlsIdentity>> identity =
//       TlsIdentity::Open(tls_options);
//   httplib::SSLServer server([&](SSL_CTX& ctx) {
//     return (*identity)->Install(&ctx);
//   });
#ifndef TPR_WEB_TLS_IDENTITY_H_
#define TPR_WEB_TLS_IDENTITY_H_

#include <openssl/ssl.h>

#include <chrono>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/statusor.h"
#include "common/tls.h"

namespace tpr::web {

// TlsIdentity: one certificate chain and key, reloaded when the files'
// modification time or size changes (checked at most every
// refresh_interval_s, during a handshake). A reload that fails keeps the
// previous identity and logs why. Thread-safe.
class TlsIdentity {
 public:
  // Open checks and reads the files. NOT_FOUND / INVALID_ARGUMENT naming
  // the file at fault (common::CheckTlsFiles).
  static absl::StatusOr<std::shared_ptr<TlsIdentity>> Open(
      const common::TlsServerOptions& options);
  ~TlsIdentity();

  // Install configures `ctx`: TLS 1.2 or later, the certificate callback
  // serving this identity (the TlsIdentity must outlive `ctx`), and with a
  // client CA, client certificates required and checked against it.
  // Returns false when OpenSSL refuses the CA file.
  bool Install(SSL_CTX* ctx);

 private:
  struct Loaded;
  explicit TlsIdentity(common::TlsServerOptions options);
  absl::Status Load();
  std::shared_ptr<Loaded> Current();
  static int OnCertificate(SSL* ssl, void* self);

  const common::TlsServerOptions options_;
  std::mutex mu_;
  std::shared_ptr<Loaded> loaded_;                 // Guarded by mu_.
  std::chrono::steady_clock::time_point checked_;  // Guarded by mu_.
  std::string stamp_;  // mtimes and sizes of the files; guarded by mu_.
};

}  // namespace tpr::web

#endif  // TPR_WEB_TLS_IDENTITY_H_
