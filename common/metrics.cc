#include "common/metrics.h"

#include <google/protobuf/descriptor.h>
#include <prometheus/collectable.h>
#include <prometheus/exposer.h>
#include <prometheus/text_serializer.h>

#include <array>
#include <chrono>
#include <exception>
#include <sstream>
#include <unordered_map>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace tpr::common {

const prometheus::Histogram::BucketBoundaries& SecondsBuckets() {
  static const auto* const buckets =
      new prometheus::Histogram::BucketBoundaries{
          0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1,
          0.25,   0.5,   1,      2.5,   5,    10,    30};
  return *buckets;
}

const prometheus::Histogram::BucketBoundaries& FineSecondsBuckets() {
  static const auto* const buckets =
      new prometheus::Histogram::BucketBoundaries{
          1e-5, 2.5e-5, 5e-5,  1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3,
          5e-3, 0.01,   0.025, 0.05, 0.1,    0.25, 1};
  return *buckets;
}

const prometheus::Histogram::BucketBoundaries& CountBuckets() {
  static const auto* const buckets =
      new prometheus::Histogram::BucketBoundaries{
          1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000, 100000};
  return *buckets;
}

struct Metrics::Families {
  explicit Families(prometheus::Registry& r)
      : requests(prometheus::BuildCounter()
                     .Name("tpr_rpc_requests_total")
                     .Help("Calls finished, by method and gRPC status code")
                     .Register(r)),
        duration(
            prometheus::BuildHistogram()
                .Name("tpr_rpc_duration_seconds")
                .Help(
                    "Call duration from metadata to status, by method and code")
                .Register(r)),
        in_flight(prometheus::BuildGauge()
                      .Name("tpr_rpc_in_flight")
                      .Help("Calls started and not yet finished, by method")
                      .Register(r)) {}

  prometheus::Family<prometheus::Counter>& requests;
  prometheus::Family<prometheus::Histogram>& duration;
  prometheus::Family<prometheus::Gauge>& in_flight;

  // Observer factories by method (ObserveMethod).
  std::mutex observers_mu;
  std::unordered_map<std::string, MessageObserverFactory> observers;

  // Observer(method): a new observer for a call of `method`, or null when
  // no service observes it. Thread-safe.
  std::unique_ptr<MessageObserver> Observer(const std::string& method) {
    std::lock_guard<std::mutex> lock(observers_mu);
    auto it = observers.find(method);
    return it == observers.end() ? nullptr : it->second();
  }

  // The series of one method, made on its first call and kept (never
  // removed) for the life of the registry. prometheus-cpp's Family::Add
  // builds a new metric (for a histogram: its buckets) and compares label
  // maps under the family's lock on every call, even when the series
  // exists; looked up here once per call instead, and a code's counter and
  // histogram once per (method, code).
  static constexpr size_t kCodes = 17;  // grpc::StatusCode OK..UNAUTHENTICATED
  struct CodeSeries {
    prometheus::Counter* requests = nullptr;
    prometheus::Histogram* duration = nullptr;
  };
  struct MethodSeries {
    prometheus::Gauge* in_flight = nullptr;
    std::array<CodeSeries, kCodes> by_code;
  };

  // Of(method): its series (the node is stable: node-based map), and in
  // *label the method label they carry. The label is the method's name
  // when the method exists (a method of a compiled-in service, or gRPC's
  // health service) and "unknown" otherwise: the name comes from the
  // client, and names it makes up must not each add series (unbounded
  // memory and scrapes). Thread-safe.
  MethodSeries& Of(const std::string& method, std::string* label) {
    std::lock_guard<std::mutex> lock(series_mu);
    auto it = series.find(method);
    if (it == series.end()) {
      const std::string name = KnownMethod(method) ? method : "unknown";
      it = series.find(name);
      if (it == series.end()) {
        it = series.try_emplace(name).first;
        it->second.in_flight = &in_flight.Add({{"method", name}});
      }
    }
    *label = it->first;
    return it->second;
  }

  // KnownMethod("/pkg.Service/Method"): whether the method is defined by a
  // service compiled into this binary (the generated descriptor pool: our
  // tpr.v1 services, reflection) or is one of gRPC's health checks (whose
  // generated code is not Protobuf's).
  static bool KnownMethod(const std::string& method) {
    if (method == "/grpc.health.v1.Health/Check" ||
        method == "/grpc.health.v1.Health/Watch") {
      return true;
    }
    const size_t slash = method.rfind('/');
    if (method.size() < 2 || method[0] != '/' || slash == 0) return false;
    const std::string full_name = absl::StrCat(method.substr(1, slash - 1), ".",
                                               method.substr(slash + 1));
    return google::protobuf::DescriptorPool::generated_pool()->FindMethodByName(
               full_name) != nullptr;
  }
  // Code(method, code): that call outcome's counter and histogram.
  // Thread-safe.
  CodeSeries Code(const std::string& method, MethodSeries& m,
                  grpc::StatusCode code) {
    auto make = [&] {
      const prometheus::Labels labels = {
          {"method", method},
          {"code",
           absl::StatusCodeToString(static_cast<absl::StatusCode>(code))}};
      return CodeSeries{&requests.Add(labels),
                        &duration.Add(labels, SecondsBuckets())};
    };
    const size_t c = static_cast<size_t>(code);
    if (c >= kCodes) return make();  // Not a code gRPC defines: not cached.
    std::lock_guard<std::mutex> lock(series_mu);
    CodeSeries& s = m.by_code[c];
    if (s.requests == nullptr) s = make();
    return s;
  }

  std::mutex series_mu;
  std::unordered_map<std::string, MethodSeries> series;  // guarded by series_mu
};

// Gauges and counters computed at scrape time.
class Metrics::GaugeCallbacks final : public prometheus::Collectable {
 public:
  void Add(std::string name, std::string help, std::function<double()> read,
           prometheus::MetricType type = prometheus::MetricType::Gauge) {
    std::lock_guard<std::mutex> lock(mu_);
    gauges_.push_back(
        {std::move(name), std::move(help), std::move(read), type});
  }

  std::vector<prometheus::MetricFamily> Collect() const override {
    std::lock_guard<std::mutex> lock(mu_);
    std::vector<prometheus::MetricFamily> out;
    for (const Gauge& g : gauges_) {
      prometheus::MetricFamily family;
      family.name = g.name;
      family.help = g.help;
      family.type = g.type;
      prometheus::ClientMetric metric;
      if (g.type == prometheus::MetricType::Counter) {
        metric.counter.value = g.read();
      } else {
        metric.gauge.value = g.read();
      }
      family.metric.push_back(std::move(metric));
      out.push_back(std::move(family));
    }
    return out;
  }

 private:
  struct Gauge {
    std::string name;
    std::string help;
    std::function<double()> read;
    prometheus::MetricType type;
  };
  mutable std::mutex mu_;
  std::vector<Gauge> gauges_;
};

namespace {

using grpc::experimental::InterceptionHookPoints;

class MetricsInterceptor final : public grpc::experimental::Interceptor {
 public:
  MetricsInterceptor(grpc::experimental::ServerRpcInfo* info,
                     Metrics::Families* families)
      : families_(families), start_(std::chrono::steady_clock::now()) {
    series_ = &families_->Of(info->method() != nullptr ? info->method() : "",
                             &method_);
    series_->in_flight->Increment();
    observer_ = families_->Observer(method_);
  }

  ~MetricsInterceptor() override {
    if (!finished_) Finish(grpc::StatusCode::CANCELLED);
    series_->in_flight->Decrement();
  }

  void Intercept(
      grpc::experimental::InterceptorBatchMethods* methods) override {
    if (observer_ != nullptr) {
      if (methods->QueryInterceptionHookPoint(
              InterceptionHookPoints::POST_RECV_MESSAGE)) {
        if (void* message = methods->GetRecvMessage())
          observer_->OnReceive(message);
      }
      if (methods->QueryInterceptionHookPoint(
              InterceptionHookPoints::PRE_SEND_MESSAGE)) {
        if (const void* message = methods->GetSendMessage())
          observer_->OnSend(message);
      }
    }
    if (methods->QueryInterceptionHookPoint(
            InterceptionHookPoints::PRE_SEND_STATUS)) {
      Finish(methods->GetSendStatus().error_code());
    }
    methods->Proceed();
  }

 private:
  void Finish(grpc::StatusCode code) {
    finished_ = true;
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_)
            .count();
    const Metrics::Families::CodeSeries s =
        families_->Code(method_, *series_, code);
    s.requests->Increment();
    s.duration->Observe(seconds);
  }

  Metrics::Families* families_;
  std::string method_;
  std::unique_ptr<MessageObserver> observer_;  // null: nobody observes it
  std::chrono::steady_clock::time_point start_;
  Metrics::Families::MethodSeries* series_ = nullptr;
  bool finished_ = false;
};

class MetricsInterceptorFactory final
    : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit MetricsInterceptorFactory(Metrics::Families* families)
      : families_(families) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(
      grpc::experimental::ServerRpcInfo* info) override {
    return new MetricsInterceptor(info, families_);
  }

 private:
  Metrics::Families* families_;
};

}  // namespace

Metrics::Metrics()
    : registry_(std::make_shared<prometheus::Registry>()),
      callbacks_(std::make_shared<GaugeCallbacks>()),
      families_(std::make_unique<Families>(*registry_)) {}

Metrics::~Metrics() = default;

absl::Status Metrics::Serve(const std::string& listen) {
  try {
    exposer_ = std::make_unique<prometheus::Exposer>(listen);
  } catch (const std::exception& e) {
    return absl::UnavailableError(absl::StrCat(
        "--metrics-listen: cannot serve /metrics on ", listen, ": ", e.what()));
  }
  exposer_->RegisterCollectable(registry_);
  exposer_->RegisterCollectable(callbacks_);
  return absl::OkStatus();
}

int Metrics::port() const {
  if (exposer_ == nullptr) return 0;
  std::vector<int> ports = exposer_->GetListeningPorts();
  return ports.empty() ? 0 : ports.front();
}

void Metrics::AddGaugeCallback(const std::string& name, const std::string& help,
                               std::function<double()> read) {
  callbacks_->Add(name, help, std::move(read));
}

void Metrics::ObserveMethod(const std::string& method,
                            MessageObserverFactory make) {
  std::lock_guard<std::mutex> lock(families_->observers_mu);
  families_->observers[method] = std::move(make);
}

void Metrics::AddCounterCallback(const std::string& name,
                                 const std::string& help,
                                 std::function<double()> read) {
  callbacks_->Add(name, help, std::move(read), prometheus::MetricType::Counter);
}

std::string Metrics::Scrape() const {
  std::vector<prometheus::MetricFamily> all = registry_->Collect();
  std::vector<prometheus::MetricFamily> gauges = callbacks_->Collect();
  all.insert(all.end(), gauges.begin(), gauges.end());
  return prometheus::TextSerializer().Serialize(all);
}

void Metrics::RecordRefused(const std::string& method, grpc::StatusCode code) {
  std::string label;
  Families::MethodSeries& series = families_->Of(method, &label);
  families_->Code(label, series, code).requests->Increment();
}

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>
Metrics::InterceptorFactory() {
  return std::make_unique<MetricsInterceptorFactory>(families_.get());
}

}  // namespace tpr::common
