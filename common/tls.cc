#include "common/tls.h"

#include <grpc/grpc_security_constants.h>
#include <grpcpp/security/tls_certificate_provider.h>
#include <grpcpp/security/tls_credentials_options.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

#include <cstdio>
#include <utility>

#include "absl/strings/str_cat.h"

namespace tpr::common {
namespace {

struct FileCloser {
  void operator()(FILE* f) const { std::fclose(f); }
};
struct X509Free {
  void operator()(X509* x) const { X509_free(x); }
};
struct KeyFree {
  void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); }
};

absl::StatusOr<std::unique_ptr<FILE, FileCloser>> Open(const std::string& path,
                                                       const char* flag) {
  if (path.empty())
    return absl::InvalidArgumentError(absl::StrCat(flag, " is required"));
  std::unique_ptr<FILE, FileCloser> f(std::fopen(path.c_str(), "rb"));
  if (f == nullptr)
    return absl::NotFoundError(absl::StrCat(flag, ": cannot read ", path));
  return f;
}

absl::StatusOr<std::unique_ptr<X509, X509Free>> ReadCert(
    const std::string& path, const char* flag) {
  absl::StatusOr<std::unique_ptr<FILE, FileCloser>> f = Open(path, flag);
  if (!f.ok()) return f.status();
  std::unique_ptr<X509, X509Free> cert(
      PEM_read_X509(f->get(), nullptr, nullptr, nullptr));
  if (cert == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat(flag, ": ", path, " holds no PEM certificate"));
  }
  return cert;
}

}  // namespace

absl::Status CheckTlsFiles(const TlsServerOptions& options) {
  absl::StatusOr<std::unique_ptr<X509, X509Free>> cert =
      ReadCert(options.cert_file, "--tls-cert");
  if (!cert.ok()) return cert.status();
  absl::StatusOr<std::unique_ptr<FILE, FileCloser>> key_file =
      Open(options.key_file, "--tls-key");
  if (!key_file.ok()) return key_file.status();
  std::unique_ptr<EVP_PKEY, KeyFree> key(
      PEM_read_PrivateKey(key_file->get(), nullptr, nullptr, nullptr));
  if (key == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat("--tls-key: ", options.key_file,
                     " holds no PEM private key (or it is "
                     "encrypted)"));
  }
  if (X509_check_private_key(cert->get(), key.get()) != 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("--tls-key: ", options.key_file,
                     " does not match the certificate ", options.cert_file));
  }
  if (!options.client_ca_file.empty()) {
    absl::StatusOr<std::unique_ptr<X509, X509Free>> ca =
        ReadCert(options.client_ca_file, "--tls-client-ca");
    if (!ca.ok()) return ca.status();
  }
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>>
MakeTlsServerCredentials(const TlsServerOptions& options) {
  if (absl::Status s = CheckTlsFiles(options); !s.ok()) return s;
  const unsigned int refresh = static_cast<unsigned int>(
      options.refresh_interval_s > 0 ? options.refresh_interval_s : 10);
  std::shared_ptr<grpc::experimental::CertificateProviderInterface> provider;
  if (options.client_ca_file.empty()) {
    provider =
        std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
            options.key_file, options.cert_file, refresh);
  } else {
    provider =
        std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
            options.key_file, options.cert_file, options.client_ca_file,
            refresh);
  }
  grpc::experimental::TlsServerCredentialsOptions tls(provider);
  tls.watch_identity_key_cert_pairs();
  if (options.client_ca_file.empty()) {
    tls.set_cert_request_type(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  } else {
    tls.watch_root_certs();
    tls.set_cert_request_type(
        GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  }
  return grpc::experimental::TlsServerCredentials(tls);
}

}  // namespace tpr::common
