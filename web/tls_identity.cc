#include "web/tls_identity.h"

#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <sys/stat.h>

#include "absl/strings/str_cat.h"
#include "common/logging.h"

namespace tpr::web {

// Loaded: one reading of the files.
struct TlsIdentity::Loaded {
  X509* leaf = nullptr;
  STACK_OF(X509) * chain = nullptr;
  EVP_PKEY* key = nullptr;
  ~Loaded() {
    if (leaf != nullptr) X509_free(leaf);
    if (chain != nullptr) sk_X509_pop_free(chain, X509_free);
    if (key != nullptr) EVP_PKEY_free(key);
  }
};

namespace {

std::string Stamp(const common::TlsServerOptions& options) {
  std::string stamp;
  for (const std::string& path : {options.cert_file, options.key_file}) {
    struct stat st {};
    if (stat(path.c_str(), &st) == 0) {
      absl::StrAppend(&stamp, st.st_mtim.tv_sec, ".", st.st_mtim.tv_nsec, ":",
                      st.st_size, ";");
    }
  }
  return stamp;
}

}  // namespace

TlsIdentity::TlsIdentity(common::TlsServerOptions options)
    : options_(std::move(options)) {}

TlsIdentity::~TlsIdentity() = default;

absl::StatusOr<std::shared_ptr<TlsIdentity>> TlsIdentity::Open(
    const common::TlsServerOptions& options) {
  if (absl::Status s = common::CheckTlsFiles(options); !s.ok()) return s;
  std::shared_ptr<TlsIdentity> identity(new TlsIdentity(options));
  if (absl::Status s = identity->Load(); !s.ok()) return s;
  return identity;
}

absl::Status TlsIdentity::Load() {
  auto loaded = std::make_shared<Loaded>();
  const std::string stamp = Stamp(options_);
  BIO* cert = BIO_new_file(options_.cert_file.c_str(), "r");
  if (cert == nullptr)
    return absl::NotFoundError(
        absl::StrCat("cannot read ", options_.cert_file));
  loaded->leaf = PEM_read_bio_X509(cert, nullptr, nullptr, nullptr);
  loaded->chain = sk_X509_new_null();
  while (X509* extra = PEM_read_bio_X509(cert, nullptr, nullptr, nullptr))
    sk_X509_push(loaded->chain, extra);
  ERR_clear_error();  // The loop ends on "no start line".
  BIO_free(cert);
  BIO* key = BIO_new_file(options_.key_file.c_str(), "r");
  if (key == nullptr)
    return absl::NotFoundError(absl::StrCat("cannot read ", options_.key_file));
  loaded->key = PEM_read_bio_PrivateKey(key, nullptr, nullptr, nullptr);
  BIO_free(key);
  if (loaded->leaf == nullptr || loaded->key == nullptr ||
      X509_check_private_key(loaded->leaf, loaded->key) != 1) {
    ERR_clear_error();
    return absl::InvalidArgumentError(
        absl::StrCat(options_.cert_file, " and ", options_.key_file,
                     " are not a PEM certificate and its private key"));
  }
  std::lock_guard<std::mutex> lock(mu_);
  loaded_ = std::move(loaded);
  stamp_ = stamp;
  checked_ = std::chrono::steady_clock::now();
  return absl::OkStatus();
}

std::shared_ptr<TlsIdentity::Loaded> TlsIdentity::Current() {
  bool reload = false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    const auto now = std::chrono::steady_clock::now();
    if (now - checked_ >= std::chrono::seconds(options_.refresh_interval_s)) {
      checked_ = now;
      reload = Stamp(options_) != stamp_;
    }
  }
  if (reload) {
    if (absl::Status s = Load(); s.ok()) {
      common::LogEvent("tpr-web", "TLS certificate reloaded");
    } else {
      common::LogWarning("tpr-web",
                         absl::StrCat("TLS reload failed, keeping the previous "
                                      "certificate: ",
                                      s.message()));
    }
  }
  std::lock_guard<std::mutex> lock(mu_);
  return loaded_;
}

int TlsIdentity::OnCertificate(SSL* ssl, void* self) {
  std::shared_ptr<Loaded> loaded = static_cast<TlsIdentity*>(self)->Current();
  // SSL_use_cert_and_key takes its own references (override = 1 replaces
  // whatever the context set).
  return SSL_use_cert_and_key(ssl, loaded->leaf, loaded->key, loaded->chain,
                              1) == 1
             ? 1
             : 0;
}

bool TlsIdentity::Install(SSL_CTX* ctx) {
  SSL_CTX_set_min_proto_version(ctx, TLS1_2_VERSION);
  SSL_CTX_set_options(ctx, SSL_OP_NO_COMPRESSION |
                               SSL_OP_NO_SESSION_RESUMPTION_ON_RENEGOTIATION);
  SSL_CTX_set_cert_cb(ctx, &TlsIdentity::OnCertificate, this);
  if (!options_.client_ca_file.empty()) {
    if (SSL_CTX_load_verify_locations(ctx, options_.client_ca_file.c_str(),
                                      nullptr) != 1) {
      return false;
    }
    SSL_CTX_set_client_CA_list(
        ctx, SSL_load_client_CA_file(options_.client_ca_file.c_str()));
    SSL_CTX_set_verify(ctx, SSL_VERIFY_PEER | SSL_VERIFY_FAIL_IF_NO_PEER_CERT,
                       nullptr);
  }
  return true;
}

}  // namespace tpr::web
