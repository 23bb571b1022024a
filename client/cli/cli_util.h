// Shared plumbing of the `tpr` subcommands: global flags, error printing,
// JSON string escaping, the progress bar and a small parallel loop.
//
//   Progress progress(items.size(), "adding");
//   ParallelFor(items.size(), jobs, [&](size_t i) { ...; progress.Step(id, "added"); });
//   if (!status.ok()) return Fail("add", status);
#ifndef TPR_CLIENT_CLI_CLI_UTIL_H_
#define TPR_CLIENT_CLI_CLI_UTIL_H_

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <google/protobuf/message.h>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "tpr/client.h"

namespace tpr::cli {

// Globals: flags every subcommand shares.
struct Globals {
  // tpr-extractor address(es). Default 127.0.0.1:7001 (or TPR_EXTRACTOR).
  std::string extractor = "127.0.0.1:7001";
  // tpr-indexer address(es). Default 127.0.0.1:7002 (or TPR_INDEXER).
  std::string indexer = "127.0.0.1:7002";
  // Machine output. Default false.
  bool json = false;
  // Deadline per call, in seconds. Default 120.
  double timeout_s = 120;
};

// CallOptionsFor returns the SDK call options of `g` (its deadline, the
// SDK's default retry policy).
tpr::client::CallOptions CallOptionsFor(const Globals& g);

// Fail prints "tpr: WHAT: STATUS" on stderr and returns exit code 1.
int Fail(const std::string& what, const absl::Status& status);

// JsonString returns `s` as a JSON string literal (RFC 8259 escaping).
std::string JsonString(absl::string_view s);

// ToJson returns `message` as one line of JSON (proto field names, every
// primitive field printed).
std::string ToJson(const google::protobuf::Message& message);

// Progress reports work done on stderr: a redrawn bar with rate and ETA on a
// terminal, one line per step otherwise ("3/9 added dog/dog_3.off ...").
// Thread-safe.
class Progress {
 public:
  // `total` steps; `what` prefixes the bar on a terminal ("" for none).
  explicit Progress(size_t total, std::string what = "");
  // Step counts one unit of work on `id` that ended as `outcome`.
  void Step(const std::string& id, const std::string& outcome);
  // Elapsed returns the seconds since construction.
  double Elapsed() const;

 private:
  using Clock = std::chrono::steady_clock;
  std::mutex mu_;
  size_t done_ = 0;
  const size_t total_;
  const std::string what_;
  const bool tty_;
  const Clock::time_point start_;
};

// ParallelFor runs fn(i) for every i in [0, n) on max(1, threads) threads,
// each taking the next index when it is free (so slow items do not hold up
// a fixed share). Returns when all are done. `fn` must be thread-safe.
template <typename Fn>
void ParallelFor(size_t n, int threads, Fn fn) {
  std::atomic<size_t> next{0};
  std::vector<std::thread> pool;
  const size_t count = std::min<size_t>(std::max(1, threads), std::max<size_t>(1, n));
  for (size_t t = 0; t < count; ++t) {
    pool.emplace_back([&] {
      for (size_t i = next++; i < n; i = next++) fn(i);
    });
  }
  for (std::thread& t : pool) t.join();
}

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_CLI_UTIL_H_
