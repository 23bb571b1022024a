// Prometheus metrics for the TPR services (prometheus-cpp), served over HTTP
// at /metrics (--metrics-listen HOST:PORT).
//
// Histograms, never summaries, so that replicas can be aggregated; no label
// takes a per-model or per-request value (ids, request ids), only the
// method and the status code (a method the binary does not define counts as
// method="unknown", so made-up names add no series). What is measured:
//   every service (a server interceptor, common/server_lifecycle.h):
//     tpr_rpc_requests_total{method,code}          counter
//     tpr_rpc_duration_seconds{method,code}        histogram
//     tpr_rpc_in_flight{method}                    gauge
//   what a service reads from its own calls' messages, through a
//   MessageObserver it registers (ObserveMethod; the extractor's stage
//   durations and upload sizes, extractor/service/extract_metrics.h; the
//   searches' counts and times, indexer/service/search_metrics.h);
// plus gauges and counters read at scrape time that each main.cc adds
// (AddGaugeCallback, AddCounterCallback): the indexer's models, indexed,
// buffered, tombstoned, tree rebuilds, storage stalls and sizes, the
// extractor's admitted calls; and families a service registers itself in
// registry() (the gateway's per-shard latency and errors, the indexer's
// RocksDB write and sync latency).
//
//   auto metrics = std::make_shared<tpr::common::Metrics>();
//   absl::Status s = metrics->Serve("127.0.0.1:9102");
//   server_options.metrics = metrics;            // StartServer installs it
#ifndef TPR_COMMON_METRICS_H_
#define TPR_COMMON_METRICS_H_

#include <grpcpp/support/server_interceptor.h>
#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/registry.h>

#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/status.h"

namespace prometheus {
class Exposer;
}  // namespace prometheus

namespace tpr::common {

class Metrics;

// MessageObserver reads the messages of one call of a method a service
// registered with Metrics::ObserveMethod, into that service's own families
// (registered in Metrics::registry()). One per call, used by one thread at
// a time, destroyed when the call ends.
class MessageObserver {
 public:
  virtual ~MessageObserver() = default;
  // OnReceive is called with each message the server receives, as the
  // interceptor sees it: the handler's request type, or a grpc::ByteBuffer
  // for a method whose handler reads raw bytes.
  virtual void OnReceive(void* message) { (void)message; }
  // OnSend is called with each message the server sends (the method's
  // response type).
  virtual void OnSend(const void* message) { (void)message; }
};

// MessageObserverFactory makes the observer of one call.
using MessageObserverFactory =
    std::function<std::unique_ptr<MessageObserver>()>;

// CallMetricsSource: a service that reads metrics from its own calls
// implements it; StartServer (common/server_lifecycle.h) calls
// AddCallMetrics once, before the server starts, when it has Metrics.
class CallMetricsSource {
 public:
  virtual ~CallMetricsSource() = default;
  // AddCallMetrics registers the service's families and observers.
  virtual void AddCallMetrics(Metrics& metrics) = 0;
};

// SecondsBuckets: histogram boundaries for call durations, 0.5 ms to 30 s (a
// cached search takes a fraction of a millisecond, an extraction of a large
// mesh tens of seconds).
const prometheus::Histogram::BucketBoundaries& SecondsBuckets();
// FineSecondsBuckets: boundaries for storage operations, 10 us to 1 s (a
// synced write is tens of microseconds on tmpfs, milliseconds on disks).
const prometheus::Histogram::BucketBoundaries& FineSecondsBuckets();
// CountBuckets: boundaries for counts per call, 1 to 100000 (the distances
// an exhaustive search of a large index computes).
const prometheus::Histogram::BucketBoundaries& CountBuckets();

// Metrics: one registry, its families, and the HTTP endpoint. Thread-safe.
class Metrics {
 public:
  Metrics();
  ~Metrics();
  Metrics(const Metrics&) = delete;
  Metrics& operator=(const Metrics&) = delete;

  // Serve starts the HTTP endpoint on `listen` ("HOST:PORT", port 0 picks a
  // free one; see port()). UNAVAILABLE when it cannot bind. Call once.
  absl::Status Serve(const std::string& listen);
  // The port Serve bound, 0 before.
  int port() const;

  // AddGaugeCallback adds a gauge `name` whose value `read` returns at each
  // scrape (called on the HTTP thread; must be thread-safe). Call before
  // Serve.
  void AddGaugeCallback(const std::string& name, const std::string& help,
                        std::function<double()> read);
  // AddCounterCallback is AddGaugeCallback for a count that only grows (a
  // Prometheus counter; `name` should end in _total).
  void AddCounterCallback(const std::string& name, const std::string& help,
                          std::function<double()> read);

  // ObserveMethod makes every later call of `method` ("/pkg.Service/Method")
  // feed a MessageObserver from `make` (replacing an earlier one for the same
  // method). Call before the server starts. Thread-safe.
  void ObserveMethod(const std::string& method, MessageObserverFactory make);

  // registry holds every family; a service registers its own there (with
  // prometheus::BuildHistogram() etc.). Thread-safe (prometheus-cpp's
  // registry and families are).
  prometheus::Registry& registry() { return *registry_; }

  // Text exposition of every metric, as /metrics serves it (for tests and
  // debugging). Cost: one pass over all series.
  std::string Scrape() const;

  // InterceptorFactory returns the server interceptor factory that records
  // the calls of a server into these metrics. The Metrics must outlive the
  // server.
  std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>
  InterceptorFactory();

  // RecordRefused counts a call the API-key check refused before any
  // handler or interceptor saw it (common/auth.h) in tpr_rpc_requests_total
  // with its method and code (UNAUTHENTICATED, PERMISSION_DENIED).
  // Thread-safe.
  void RecordRefused(const std::string& method, grpc::StatusCode code);

  // For the interceptor (metrics.cc).
  struct Families;
  Families& families() { return *families_; }

 private:
  class GaugeCallbacks;
  std::shared_ptr<prometheus::Registry> registry_;
  std::shared_ptr<GaugeCallbacks> callbacks_;
  std::unique_ptr<Families> families_;
  std::unique_ptr<prometheus::Exposer> exposer_;
};

}  // namespace tpr::common

#endif  // TPR_COMMON_METRICS_H_
