// How `tpr` reaches the services: the global flags every subcommand shares
// (addresses, deadline, output mode) and the one place that turns them into
// SDK clients and call options. Flags that change how a connection is made
// (credentials, TLS) belong in Globals, AddGlobalFlags and Connect*, and
// nowhere else.
//
//   Globals g;  AddGlobalFlags(&app, &g);   // before parsing
//   std::optional<IndexerClient> indexer = ConnectIndexer(g);
//   if (!indexer) return 2;                 // the reason is reported
//   indexer->Stats(&CallOptionsFor(g));
#ifndef TPR_CLIENT_CLI_CONNECTION_H_
#define TPR_CLIENT_CLI_CONNECTION_H_

#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "tpr/client.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace CLI {
class App;
}  // namespace CLI

namespace tpr::cli {

// Globals: flags every subcommand shares.
struct Globals {
  // tpr-extractor address(es). Default 127.0.0.1:7001 (or TPR_EXTRACTOR).
  std::string extractor = "127.0.0.1:7001";
  // tpr-indexer address(es). Default 127.0.0.1:7002 (or TPR_INDEXER).
  std::string indexer = "127.0.0.1:7002";
  // Machine output: one JSON object per line. Default false.
  bool json = false;
  // Deadline per call, in seconds. Default 120.
  double timeout_s = 120;
  // TLS and API key (--tls, --tls-ca, --tls-cert, --tls-key,
  // --tls-server-name, --api-key or TPR_API_KEY). Default: plaintext, no
  // key.
  tpr::client::ConnectionOptions connection;
  // -v: print each call's method, status and request id on stderr.
  // Default false.
  bool verbose = false;
};

// AddGlobalFlags declares --extractor, --indexer, --json, --timeout, the TLS
// flags, --api-key and -v on `app`, storing into `*g` (which must outlive
// parsing).
void AddGlobalFlags(CLI::App* app, Globals* g);

// CallOptionsFor returns the SDK call options of `g` (its deadline, the
// SDK's default retry policy).
tpr::client::CallOptions CallOptionsFor(const Globals& g);

// ConnectExtractor returns a client for g.extractor, or reports
// "--extractor: <reason>" (Fail) and returns nullopt, a usage error (exit
// 2: e.g. an address without a port, a missing TLS file). Connection itself
// happens at the first call.
std::optional<tpr::client::ExtractorClient> ConnectExtractor(const Globals& g);

// ConnectIndexer is ConnectExtractor for g.indexer.
std::optional<tpr::client::IndexerClient> ConnectIndexer(const Globals& g);

// AdminTarget: one tpr-indexer's IndexerAdmin stub (backup, restore,
// promote) and the call deadline of `g`.
struct AdminTarget {
  std::unique_ptr<tpr::v1::IndexerAdmin::Stub> stub;
  // Prepares a call: deadline from g.timeout_s, request-id reporting.
  std::function<void(grpc::ClientContext*)> prepare;
};

// ConnectAdmin returns the admin stub of g.indexer, which must name exactly
// one tpr-indexer (admin calls address one process: a shard's primary or a
// follower, never a gateway or a replica list); prints the reason and
// returns nullopt otherwise.
std::optional<AdminTarget> ConnectAdmin(const Globals& g);

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_CONNECTION_H_
