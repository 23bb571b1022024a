#include "client/cli/connection.h"

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <string>

#include "client/cli/cli_util.h"

namespace tpr::cli {

void AddGlobalFlags(CLI::App* app, Globals* g) {
  app->add_option("--extractor", g->extractor,
                  "tpr-extractor address(es), HOST:PORT[,HOST:PORT]")
      ->envname("TPR_EXTRACTOR")
      ->capture_default_str();
  app->add_option("--indexer", g->indexer,
                  "tpr-indexer address(es), HOST:PORT[,HOST:PORT]")
      ->envname("TPR_INDEXER")
      ->capture_default_str();
  app->add_flag("--json", g->json, "machine output: one JSON object per line");
  app->add_option("--timeout", g->timeout_s, "deadline per call, in seconds")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  tpr::client::ConnectionOptions& c = g->connection;
  app->add_flag("--tls", c.tls, "connect over TLS")->envname("TPR_TLS");
  app->add_option("--tls-ca", c.tls_ca_file,
                  "PEM authority to trust (default: the system's roots)")
      ->envname("TPR_TLS_CA");
  app->add_option("--tls-cert", c.tls_cert_file,
                  "PEM client certificate, for servers requiring mutual TLS")
      ->envname("TPR_TLS_CERT");
  app->add_option("--tls-key", c.tls_key_file, "PEM private key of --tls-cert")
      ->envname("TPR_TLS_KEY");
  app->add_option(
      "--tls-server-name", c.tls_server_name,
      "name the server's certificate must carry, when not the address's host");
  app->add_option("--api-key", c.api_key,
                  "API key sent as 'authorization: Bearer KEY' (prefer "
                  "TPR_API_KEY: a flag "
                  "shows in ps)")
      ->envname("TPR_API_KEY");
  app->add_flag("-v,--verbose", g->verbose,
                "print each call's method, status and request id on stderr");
}

namespace {

// The SDK connection options of `g`, with -v's reporting attached.
tpr::client::ConnectionOptions ConnectionFor(const Globals& g) {
  tpr::client::ConnectionOptions connection = g.connection;
  if (g.verbose) {
    connection.on_call_done = [](absl::string_view method,
                                 absl::string_view request_id,
                                 const grpc::Status& status) {
      const std::string code = absl::StatusCodeToString(
          static_cast<absl::StatusCode>(status.error_code()));
      std::fprintf(stderr, "tpr: %.*s: %s request_id=%.*s\n",
                   static_cast<int>(method.size()), method.data(), code.c_str(),
                   static_cast<int>(request_id.size()), request_id.data());
    };
  }
  return connection;
}

}  // namespace

tpr::client::CallOptions CallOptionsFor(const Globals& g) {
  tpr::client::CallOptions call;
  call.timeout = absl::Seconds(g.timeout_s);
  return call;
}

std::optional<tpr::client::ExtractorClient> ConnectExtractor(const Globals& g) {
  absl::StatusOr<tpr::client::ExtractorClient> client =
      tpr::client::ExtractorClient::Connect(g.extractor, ConnectionFor(g),
                                            CallOptionsFor(g));
  if (!client.ok()) {
    Fail("--extractor", client.status());
    return std::nullopt;
  }
  return *std::move(client);
}

std::optional<tpr::client::IndexerClient> ConnectIndexer(const Globals& g) {
  absl::StatusOr<tpr::client::IndexerClient> client =
      tpr::client::IndexerClient::Connect(g.indexer, ConnectionFor(g),
                                          CallOptionsFor(g));
  if (!client.ok()) {
    Fail("--indexer", client.status());
    return std::nullopt;
  }
  return *std::move(client);
}

std::optional<AdminTarget> ConnectAdmin(const Globals& g) {
  if (g.indexer.find(',') != std::string::npos) {
    Fail(
        "--indexer",
        absl::InvalidArgumentError(
            "admin commands address one tpr-indexer; give a single HOST:PORT"));
    return std::nullopt;
  }
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
      tpr::client::MakeChannel(g.indexer, ConnectionFor(g));
  if (!channel.ok()) {
    Fail("--indexer", channel.status());
    return std::nullopt;
  }
  AdminTarget target;
  target.stub = tpr::v1::IndexerAdmin::NewStub(*channel);
  const double timeout_s = g.timeout_s;
  target.prepare = [timeout_s](grpc::ClientContext* context) {
    context->set_deadline(
        std::chrono::system_clock::now() +
        std::chrono::milliseconds(static_cast<int64_t>(timeout_s * 1000)));
  };
  return target;
}

}  // namespace tpr::cli
