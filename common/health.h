// Liveness and readiness through the standard gRPC health service
// (grpc.health.v1.Health, enabled by StartServer):
//   - the overall status (service "") is liveness: SERVING from start until
//     shutdown begins;
//   - the status of the service's own name ("tpr.v1.Indexer",
//     "tpr.v1.Extractor") is readiness: NOT_SERVING while the check below
//     reports a reason (loading, a follower catching up, the disk full) and
//     from the moment draining starts.
// Kubernetes probes them natively (`grpc: {port: 7002, service: ...}`).
#ifndef TPR_COMMON_HEALTH_H_
#define TPR_COMMON_HEALTH_H_

#include <grpcpp/server.h>

#include <condition_variable>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

namespace tpr::common {

// ReadinessCheck returns "" when the service is ready, else a short reason
// ("disk full", "catching up with the leader"). Called on the monitor's
// thread; must be thread-safe and cheap.
using ReadinessCheck = std::function<std::string()>;

// SetReadiness sets the health status of `service` on `server`. No-op when
// the server has no health service. Thread-safe.
void SetReadiness(grpc::Server& server, const std::string& service, bool ready);

// ReadinessMonitor polls a ReadinessCheck every poll_ms and mirrors it into
// the health status of `service`, logging each change ("not ready: disk
// full", "ready"). The first poll happens in the constructor, so the status
// is right before the first probe. Stop() (or the destructor) ends polling
// and leaves the status NOT_SERVING (draining). Thread-safe.
class ReadinessMonitor {
 public:
  ReadinessMonitor(grpc::Server* server, std::string service,
                   ReadinessCheck check, int poll_ms, std::string log_name);
  ~ReadinessMonitor();
  ReadinessMonitor(const ReadinessMonitor&) = delete;
  ReadinessMonitor& operator=(const ReadinessMonitor&) = delete;

  // Stop ends polling, then sets the status NOT_SERVING. Idempotent.
  void Stop();

 private:
  void PollOnce();
  void Run();

  grpc::Server* server_;
  const std::string service_;
  const ReadinessCheck check_;
  const int poll_ms_;
  const std::string log_name_;
  std::string last_reason_ = "\x01";  // Neither "" nor any real reason.
  std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace tpr::common

#endif  // TPR_COMMON_HEALTH_H_
