#include "common/health.h"

#include <grpcpp/health_check_service_interface.h>

#include <chrono>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/logging.h"

namespace tpr::common {

void SetReadiness(grpc::Server& server, const std::string& service,
                  bool ready) {
  if (grpc::HealthCheckServiceInterface* health =
          server.GetHealthCheckService()) {
    health->SetServingStatus(service, ready);
  }
}

ReadinessMonitor::ReadinessMonitor(grpc::Server* server, std::string service,
                                   ReadinessCheck check, int poll_ms,
                                   std::string log_name)
    : server_(server),
      service_(std::move(service)),
      check_(std::move(check)),
      poll_ms_(poll_ms > 0 ? poll_ms : 1000),
      log_name_(std::move(log_name)) {
  PollOnce();
  thread_ = std::thread([this] { Run(); });
}

ReadinessMonitor::~ReadinessMonitor() { Stop(); }

void ReadinessMonitor::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_ && !thread_.joinable()) return;
    stopping_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  SetReadiness(*server_, service_, false);
}

void ReadinessMonitor::PollOnce() {
  const std::string reason = check_ ? check_() : "";
  if (reason == last_reason_) return;
  last_reason_ = reason;
  SetReadiness(*server_, service_, reason.empty());
  LogEvent(log_name_, reason.empty()
                          ? absl::StrCat(service_, " ready")
                          : absl::StrCat(service_, " not ready: ", reason));
}

void ReadinessMonitor::Run() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!cv_.wait_for(lock, std::chrono::milliseconds(poll_ms_),
                       [&] { return stopping_; })) {
    lock.unlock();
    PollOnce();
    lock.lock();
  }
}

}  // namespace tpr::common
