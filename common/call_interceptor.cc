#include "common/call_interceptor.h"

#include <chrono>
#include <utility>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"

namespace tpr::common {
namespace {

using grpc::experimental::InterceptionHookPoints;

class CallInterceptor final : public grpc::experimental::Interceptor {
 public:
  CallInterceptor(grpc::experimental::ServerRpcInfo* info,
                  std::shared_ptr<const CallInterceptorOptions> options)
      : info_(info),
        options_(std::move(options)),
        start_(std::chrono::steady_clock::now()) {
    record_.method = info->method() != nullptr ? info->method() : "";
  }

  ~CallInterceptor() override {
    // A call torn down without sending a status (the client went away
    // before the handler answered) still counts, as CANCELLED.
    if (!finished_) {
      record_.code = 1;
      Finish();
    }
  }

  void Intercept(
      grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(
            InterceptionHookPoints::POST_RECV_INITIAL_METADATA)) {
      // The peer is known from here on, not when the interceptor is made.
      if (info_->server_context() != nullptr)
        record_.peer = info_->server_context()->peer();
      std::multimap<grpc::string_ref, grpc::string_ref>* md =
          methods->GetRecvInitialMetadata();
      auto it = md->find(kRequestIdHeader);
      if (it != md->end()) {
        record_.request_id = SanitizeRequestId(
            absl::string_view(it->second.data(), it->second.size()));
      }
      if (record_.request_id.empty()) {
        record_.request_id = NewRequestId();
        if (it != md->end()) md->erase(it);
        // Both strings outlive the call: the key is static, the value is
        // owned by this interceptor, which gRPC destroys with the call.
        md->emplace(grpc::string_ref(kRequestIdHeader),
                    grpc::string_ref(record_.request_id));
      }
    }
    if (methods->QueryInterceptionHookPoint(
            InterceptionHookPoints::POST_RECV_MESSAGE) &&
        methods->GetRecvMessage() == nullptr) {
      // No message: the end of a client stream, or bytes that did not parse.
      recv_failed_ = true;
    }
    if (methods->QueryInterceptionHookPoint(
            InterceptionHookPoints::PRE_SEND_STATUS)) {
      grpc::Status status = methods->GetSendStatus();
      if (recv_failed_ && status.error_code() == grpc::StatusCode::INTERNAL &&
          status.error_message().empty()) {
        // gRPC answers a request that does not parse with INTERNAL and no
        // message (proto_utils.h); it is the caller's input at fault.
        status = grpc::Status(
            grpc::StatusCode::INVALID_ARGUMENT,
            absl::StrCat(
                "the request does not parse as ", record_.method,
                "'s message: malformed protobuf bytes, or a string field "
                "(such as an id or label) that is not valid UTF-8"));
        methods->ModifySendStatus(status);
      }
      record_.code = static_cast<int>(status.error_code());
      record_.status_message = status.error_message();
      if (!record_.request_id.empty()) {
        methods->GetSendTrailingMetadata()->emplace(kRequestIdHeader,
                                                    record_.request_id);
      }
      Finish();
    }
    methods->Proceed();
  }

 private:
  void Finish() {
    finished_ = true;
    record_.duration_ms = std::chrono::duration<double, std::milli>(
                              std::chrono::steady_clock::now() - start_)
                              .count();
    for (const CallObserver& observer : options_->observers) observer(record_);
    if (options_->log_calls &&
        !absl::StartsWith(record_.method, "/grpc.health.") &&
        !absl::StartsWith(record_.method, "/grpc.reflection.")) {
      LogCall(options_->service, record_);
    }
  }

  grpc::experimental::ServerRpcInfo* const info_;
  std::shared_ptr<const CallInterceptorOptions> options_;
  std::chrono::steady_clock::time_point start_;
  CallRecord record_;
  bool finished_ = false;
  bool recv_failed_ = false;  // a POST_RECV_MESSAGE without a message
};

class CallInterceptorFactory final
    : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit CallInterceptorFactory(CallInterceptorOptions options)
      : options_(std::make_shared<const CallInterceptorOptions>(
            std::move(options))) {}

  grpc::experimental::Interceptor* CreateServerInterceptor(
      grpc::experimental::ServerRpcInfo* info) override {
    return new CallInterceptor(info, options_);
  }

 private:
  std::shared_ptr<const CallInterceptorOptions> options_;
};

}  // namespace

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>
MakeCallInterceptorFactory(CallInterceptorOptions options) {
  return std::make_unique<CallInterceptorFactory>(std::move(options));
}

std::string RequestIdOf(const grpc::ServerContextBase& context) {
  const auto& md = context.client_metadata();
  auto it = md.find(kRequestIdHeader);
  if (it == md.end()) return "";
  return std::string(it->second.data(), it->second.size());
}

}  // namespace tpr::common
