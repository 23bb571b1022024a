// tpr-soak: a bounded soak of a real tpr-indexer process on loopback.
//
//   tpr-soak --seconds 600 --indexer build/indexer/tpr-indexer
//
// Rounds until the time is up: writer threads add, update and delete models
// and searcher threads search, all through the SDK, against a tpr-indexer
// child process; after a random 1-6 s the child gets SIGKILL mid-traffic.
// It is then restarted on the same data directory and checked against an
// oracle kept in this process:
//   - every acknowledged write is there: Get of every id of the key space
//     returns the last acknowledged version (or NOT_FOUND after an
//     acknowledged delete). A write that was in flight at the kill may have
//     landed or not; either outcome is accepted and adopted. Anything else
//     is a loss (an acknowledged write missing) or a phantom (a model that
//     was deleted or never written);
//   - Stats counts the models the oracle holds;
//   - searches (by signature and by id, random k, some with a label filter
//     or exclude_self) equal brute force over the acknowledged state: every
//     EMD computed in-process (tests/service/indexer_testing.h, over
//     indexer/lib/emd.h), independent of the server's VP-tree and buffer.
// At the end the indexer is stopped with SIGTERM, restarted and checked once
// more (the clean-shutdown path). Each writer owns a disjoint share of the
// ids, so per-id order is the writer's program order and the oracle is
// exact without locking.
//
// Prints operations by kind, kills, losses, phantoms, wrong answers and
// p50/p99 latencies; exits 1 if losses, phantoms, wrong answers or errors
// outside a kill are non-zero. Ports are free ports of 127.0.0.1; the work
// directory (a fresh mkdtemp one unless --work-dir) is removed on success.
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "CLI/CLI.hpp"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "tests/indexer/signature_testing.h"
#include "tests/service/indexer_testing.h"
#include "tpr/client.h"

namespace tpr::soak {
namespace {

using Clock = std::chrono::steady_clock;
using indexer::testing::BruteForce;
using indexer::testing::Hit;
using indexer::testing::TestModel;
using indexer::testing::ToWire;

struct Options {
  std::string indexer_binary;
  double seconds = 60;
  int writers = 3;
  int searchers = 2;
  int ids = 300;
  double min_run_seconds = 1.0;
  double max_run_seconds = 6.0;
  int verify_searches = 30;
  uint64_t seed = 1;
  std::string work_dir;
  bool keep = false;
};

// ---------------------------------------------------------------------------
// The indexer child process.

int FreePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return 0;
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof addr;
  int port = 0;
  if (bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0) {
    port = ntohs(addr.sin_port);
  }
  close(fd);
  return port;
}

// Listening returns whether 127.0.0.1:port accepts a TCP connection.
bool Listening(int port) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return false;
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(static_cast<uint16_t>(port));
  const bool ok =
      connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0;
  close(fd);
  return ok;
}

// The running child, for the signal handler and the watchdog.
std::atomic<pid_t> g_child{0};

void KillChildAndExit(int sig) {
  const pid_t pid = g_child.load();
  if (pid > 0) kill(pid, SIGKILL);
  _exit(128 + sig);
}

// IndexerProcess runs tpr-indexer on one data directory, appending its
// stderr to a log file; restartable.
class IndexerProcess {
 public:
  IndexerProcess(std::string binary, std::string data_dir, std::string log_path)
      : binary_(std::move(binary)),
        data_dir_(std::move(data_dir)),
        log_path_(std::move(log_path)) {}
  ~IndexerProcess() { Kill9(); }

  // Start launches the child (on the previous port when there was one, so
  // clients could keep their address; a fresh port if that fails) and waits
  // until it answers Stats. Returns how long the restart took.
  absl::StatusOr<double> Start() {
    const Clock::time_point start = Clock::now();
    absl::Status last;
    for (int attempt = 0; attempt < 4; ++attempt) {
      if (port_ == 0 || attempt > 0) port_ = FreePort();
      if (port_ == 0) return absl::UnavailableError("no free loopback port");
      last = Launch();
      if (last.ok()) {
        return std::chrono::duration<double>(Clock::now() - start).count();
      }
    }
    return last;
  }

  // Kill9 sends SIGKILL and reaps the child. No-op when not running.
  void Kill9() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = 0;
    g_child = 0;
  }

  // Terminate sends SIGTERM and waits up to 60 s for a clean exit (then
  // SIGKILL). Returns INTERNAL unless the child exited with status 0.
  absl::Status Terminate() {
    if (pid_ <= 0) return absl::OkStatus();
    kill(pid_, SIGTERM);
    for (int i = 0; i < 600; ++i) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = 0;
        g_child = 0;
        if (WIFEXITED(status) && WEXITSTATUS(status) == 0)
          return absl::OkStatus();
        return absl::InternalError(
            absl::StrCat("tpr-indexer exited with status ", status,
                         " after SIGTERM (log: ", log_path_, ")"));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    Kill9();
    return absl::InternalError(
        "tpr-indexer did not exit within 60 s of SIGTERM");
  }

  std::string address() const { return absl::StrCat("127.0.0.1:", port_); }

 private:
  absl::Status Launch() {
    const std::string listen = address();
    const pid_t parent = getpid();
    const pid_t pid = fork();
    if (pid < 0) return absl::InternalError("fork failed");
    if (pid == 0) {
      // The child dies with us, whatever ends us.
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (getppid() != parent) _exit(127);
      const int fd =
          open(log_path_.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      if (fd >= 0) {
        dup2(fd, 1);
        dup2(fd, 2);
        close(fd);
      }
      execl(binary_.c_str(), binary_.c_str(), "--listen", listen.c_str(),
            "--data-dir", data_dir_.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    pid_ = pid;
    g_child = pid;
    client::CallOptions call;
    call.timeout = absl::Seconds(2);
    call.max_attempts = 1;
    const Clock::time_point deadline = Clock::now() + std::chrono::seconds(60);
    while (Clock::now() < deadline) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = 0;
        g_child = 0;
        return absl::UnavailableError(
            absl::StrCat("tpr-indexer exited at start (status ", status,
                         "); log: ", log_path_));
      }
      // Poll the port with plain connects: a gRPC channel that found the
      // port closed waits out its reconnect backoff, which would blur the
      // measured restart time. Once it accepts, Stats must answer.
      if (Listening(port_)) {
        absl::StatusOr<client::IndexerClient> client =
            client::IndexerClient::Connect(listen);
        if (!client.ok()) return client.status();
        if (client->Stats(&call).ok()) return absl::OkStatus();
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    Kill9();
    return absl::DeadlineExceededError("tpr-indexer not serving within 60 s");
  }

  std::string binary_;
  std::string data_dir_;
  std::string log_path_;
  int port_ = 0;
  pid_t pid_ = 0;
};

// ---------------------------------------------------------------------------
// The oracle.

// Version: one state of an id. version numbers are unique per id.
struct Version {
  bool present = false;
  int64_t version = 0;
  std::string label;
  index::Signature signature;
};

// Slot: what is known about one id. Only its writer touches it while a
// round runs; the verifier reads it between rounds.
struct Slot {
  std::string id;
  Version acked;
  // A write whose outcome is unknown (in flight at the kill): either it
  // landed or `acked` still holds. The writer leaves the id alone until the
  // verifier resolves it.
  std::optional<Version> pending;
};

v1::Model ToModel(const std::string& id, const Version& v) {
  v1::Model m;
  m.set_id(id);
  m.set_label(v.label);
  (*m.mutable_metadata())["version"] = std::to_string(v.version);
  *m.mutable_signature() = ToWire(v.signature);
  return m;
}

// Matches returns whether the stored model is version `v`.
bool Matches(const v1::Model& stored, const std::string& id, const Version& v) {
  if (!v.present) return false;
  const auto it = stored.metadata().find("version");
  return stored.id() == id && it != stored.metadata().end() &&
         it->second == std::to_string(v.version) && stored.label() == v.label &&
         stored.signature().SerializeAsString() ==
             ToWire(v.signature).SerializeAsString();
}

// ---------------------------------------------------------------------------
// Figures.

enum Kind { kAdd, kUpdate, kDelete, kSearch, kKinds };
const char* const kKindNames[kKinds] = {"add", "update", "delete", "search"};

struct Figures {
  std::mutex mu;
  std::vector<double> latency_ms[kKinds];  // acknowledged operations only
  int64_t failed_at_kill = 0;              // operations cut off by a kill
  int64_t unexpected_errors = 0;  // operations failed with the server up
  int64_t kills = 0;
  int64_t rounds = 0;
  int64_t resolved_landed = 0;  // in-flight writes found applied
  int64_t resolved_not_landed = 0;
  int64_t losses = 0;
  int64_t phantoms = 0;
  int64_t wrong_answers = 0;
  int64_t verified_gets = 0;
  int64_t verified_searches = 0;
  std::vector<double> restart_seconds;

  void Add(Kind kind, double ms) {
    std::lock_guard<std::mutex> lock(mu);
    latency_ms[kind].push_back(ms);
  }
  void Error(bool killed, const std::string& what) {
    std::lock_guard<std::mutex> lock(mu);
    if (killed) {
      ++failed_at_kill;
    } else {
      ++unexpected_errors;
      std::fprintf(stderr, "soak: error with the server up: %s\n",
                   what.c_str());
    }
  }
  void Wrong(const std::string& what) {
    std::lock_guard<std::mutex> lock(mu);
    ++wrong_answers;
    std::fprintf(stderr, "soak: WRONG: %s\n", what.c_str());
  }
};

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t i = std::min(
      v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size())));
  return v[i];
}

double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

// ---------------------------------------------------------------------------
// Traffic.

class Soak {
 public:
  explicit Soak(const Options& options)
      : options_(options), rng_(options.seed) {
    index::testing::SignatureGeneratorOptions gen;
    gen.seed = options.seed;
    gen.features = 12;
    gen.bands = 8;
    gen.classes = 5;
    for (int w = 0; w < options.writers + options.searchers + 1; ++w) {
      gen.seed = options.seed * 1000 + static_cast<uint64_t>(w);
      generators_.push_back(
          std::make_unique<index::testing::SignatureGenerator>(gen));
    }
    for (int i = 0; i < options.ids; ++i) {
      slots_.push_back(
          Slot{absl::StrFormat("s%05d", i), Version{}, std::nullopt});
    }
  }

  // Run returns the process exit code.
  int Run(IndexerProcess* server) {
    const Clock::time_point start = Clock::now();
    const auto left = [&] {
      return options_.seconds -
             std::chrono::duration<double>(Clock::now() - start).count();
    };
    if (!Restart(server)) return 1;
    std::uniform_real_distribution<double> run_for(options_.min_run_seconds,
                                                   options_.max_run_seconds);
    while (left() > 0) {
      const double seconds = std::min(run_for(rng_), std::max(0.2, left()));
      RunTraffic(server, seconds, /*kill_at_end=*/true);
      if (!Restart(server)) return 1;
      Verify(server->address());
    }
    // The clean path: SIGTERM, restart, verify.
    if (absl::Status s = server->Terminate(); !s.ok()) {
      figures_.Wrong(s.ToString());
    } else if (Restart(server)) {
      Verify(server->address());
    }
    server->Terminate().IgnoreError();
    Report(std::chrono::duration<double>(Clock::now() - start).count());
    const bool ok = figures_.losses == 0 && figures_.phantoms == 0 &&
                    figures_.wrong_answers == 0 &&
                    figures_.unexpected_errors == 0;
    return ok ? 0 : 1;
  }

 private:
  bool Restart(IndexerProcess* server) {
    absl::StatusOr<double> took = server->Start();
    if (!took.ok()) {
      std::fprintf(stderr, "soak: cannot (re)start tpr-indexer: %s\n",
                   took.status().ToString().c_str());
      ++figures_.wrong_answers;
      return false;
    }
    figures_.restart_seconds.push_back(*took);
    return true;
  }

  void RunTraffic(IndexerProcess* server, double seconds, bool kill_at_end) {
    ++figures_.rounds;
    absl::StatusOr<client::IndexerClient> client =
        client::IndexerClient::Connect(server->address());
    if (!client.ok()) {
      figures_.Wrong(client.status().ToString());
      return;
    }
    std::atomic<bool> stop{false};
    std::atomic<bool> killed{false};
    std::vector<std::thread> threads;
    for (int w = 0; w < options_.writers; ++w) {
      threads.emplace_back([&, w] { Writer(*client, w, stop, killed); });
    }
    for (int s = 0; s < options_.searchers; ++s) {
      threads.emplace_back(
          [&, s] { Searcher(*client, options_.writers + s, stop, killed); });
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    if (kill_at_end) {
      killed = true;  // set first: every failure from here on is the kill's
      server->Kill9();
      ++figures_.kills;
    }
    stop = true;
    for (std::thread& t : threads) t.join();
  }

  static client::CallOptions CallTimeout() {
    client::CallOptions call;
    call.timeout = absl::Seconds(10);
    call.max_attempts = 1;
    return call;
  }

  void Writer(const client::IndexerClient& client, int w,
              const std::atomic<bool>& stop, const std::atomic<bool>& killed) {
    std::mt19937_64 rng(options_.seed * 7919 +
                        static_cast<uint64_t>(w) * 104729 +
                        static_cast<uint64_t>(figures_.rounds));
    index::testing::SignatureGenerator& gen =
        *generators_[static_cast<size_t>(w)];
    std::vector<size_t> mine;
    for (size_t i = static_cast<size_t>(w); i < slots_.size();
         i += static_cast<size_t>(options_.writers)) {
      mine.push_back(i);
    }
    std::uniform_int_distribution<size_t> pick(0, mine.size() - 1);
    std::uniform_real_distribution<double> unit(0, 1);
    const client::CallOptions call = CallTimeout();
    while (!stop && !killed) {
      Slot& slot = slots_[mine[pick(rng)]];
      if (slot.pending) {
        std::this_thread::yield();  // left alone until the verifier resolves it
        continue;
      }
      Version next;
      next.version = slot.acked.version + 1;
      Kind kind;
      if (!slot.acked.present) {
        kind = kAdd;
      } else {
        kind = unit(rng) < 0.6 ? kUpdate : kDelete;
      }
      if (kind != kDelete) {
        const int c = static_cast<int>(rng() % 5);
        next.present = true;
        next.label = absl::StrCat("c", c);
        next.signature = gen.Member(c);
      }
      const Clock::time_point t0 = Clock::now();
      absl::Status status;
      if (kind == kDelete) {
        status = client.Delete(slot.id, &call);
      } else {
        absl::StatusOr<bool> created = client.Upsert(
            ToModel(slot.id, next), /*overwrite=*/kind == kUpdate, &call);
        status = created.status();
        if (created.ok() && *created != (kind == kAdd)) {
          figures_.Wrong(
              absl::StrCat(slot.id, ": upsert said created=", *created));
        }
      }
      if (status.ok()) {
        figures_.Add(kind, MsSince(t0));
        slot.acked = std::move(next);
      } else {
        // The outcome is unknown: it may have landed before the kill.
        slot.pending = std::move(next);
        figures_.Error(killed, absl::StrCat(kKindNames[kind], " ", slot.id,
                                            ": ", status.ToString()));
      }
    }
  }

  void Searcher(const client::IndexerClient& client, int g,
                const std::atomic<bool>& stop,
                const std::atomic<bool>& killed) {
    std::mt19937_64 rng(options_.seed * 31 + static_cast<uint64_t>(g));
    index::testing::SignatureGenerator& gen =
        *generators_[static_cast<size_t>(g)];
    const client::CallOptions call = CallTimeout();
    while (!stop && !killed) {
      v1::SearchRequest request;
      *request.mutable_signature() = ToWire(gen.Next());
      request.set_k(1 + static_cast<int>(rng() % 10));
      const Clock::time_point t0 = Clock::now();
      std::unique_ptr<client::SearchStream> stream =
          client.Search(request, &call);
      std::vector<v1::Neighbor> got;
      for (v1::Neighbor n; stream->Next(&n);) got.push_back(n);
      const absl::Status status = stream->Finish();
      if (!status.ok()) {
        figures_.Error(killed, absl::StrCat("search: ", status.ToString()));
        continue;
      }
      figures_.Add(kSearch, MsSince(t0));
      // The state moves under a running search, so only the shape is
      // checked here; exactness is checked between rounds.
      for (size_t i = 1; i < got.size(); ++i) {
        if (got[i].distance() < got[i - 1].distance()) {
          figures_.Wrong("search results out of order under writes");
        }
      }
      if (got.size() > static_cast<size_t>(request.k()))
        figures_.Wrong("more than k results");
    }
  }

  // Verify checks every id and a batch of searches against the oracle,
  // resolving writes that were in flight at the kill.
  void Verify(const std::string& address) {
    absl::StatusOr<client::IndexerClient> client =
        client::IndexerClient::Connect(address);
    if (!client.ok()) {
      figures_.Wrong(client.status().ToString());
      return;
    }
    const client::CallOptions call = CallTimeout();
    for (Slot& slot : slots_) {
      absl::StatusOr<v1::Model> stored = client->Get(slot.id, &call);
      ++figures_.verified_gets;
      if (!stored.ok() &&
          stored.status().code() != absl::StatusCode::kNotFound) {
        figures_.Wrong(
            absl::StrCat("get ", slot.id, ": ", stored.status().ToString()));
        continue;
      }
      const bool present = stored.ok();
      const auto is = [&](const Version& v) {
        return present ? Matches(*stored, slot.id, v) : !v.present;
      };
      if (is(slot.acked)) {
        if (slot.pending) ++figures_.resolved_not_landed;
      } else if (slot.pending && is(*slot.pending)) {
        ++figures_.resolved_landed;
        slot.acked = *slot.pending;
      } else if (slot.acked.present) {
        ++figures_.losses;
        std::string found = "nothing";
        if (present) {
          const auto it = stored->metadata().find("version");
          found = it == stored->metadata().end()
                      ? "a model without a version"
                      : absl::StrCat("version ", it->second);
        }
        std::fprintf(stderr,
                     "soak: LOSS: %s version %lld acknowledged, found %s\n",
                     slot.id.c_str(),
                     static_cast<long long>(slot.acked.version), found.c_str());
      } else {
        ++figures_.phantoms;
        std::fprintf(stderr,
                     "soak: PHANTOM: %s acknowledged absent, found a model\n",
                     slot.id.c_str());
      }
      slot.pending.reset();
    }

    std::vector<TestModel> state;
    for (const Slot& slot : slots_) {
      if (slot.acked.present)
        state.push_back({slot.id, slot.acked.label, slot.acked.signature});
    }
    absl::StatusOr<v1::StatsResponse> stats = client->Stats(&call);
    if (!stats.ok() || stats->models() != static_cast<int64_t>(state.size())) {
      figures_.Wrong(absl::StrCat("stats: ",
                                  stats.ok() ? std::to_string(stats->models())
                                             : stats.status().ToString(),
                                  " models, oracle ", state.size()));
    }
    index::testing::SignatureGenerator& gen = *generators_.back();
    for (int q = 0; q < options_.verify_searches; ++q) {
      v1::SearchRequest request;
      request.set_k(1 + static_cast<int>(rng_() % 20));
      index::Signature query;
      std::string exclude;
      if (q % 2 == 0 || state.empty()) {
        query = gen.Next();
        *request.mutable_signature() = ToWire(query);
      } else {
        const TestModel& m = state[rng_() % state.size()];
        query = m.signature;
        request.set_id(m.id);
        if (rng_() % 2 == 0) {
          request.set_exclude_self(true);
          exclude = m.id;
        }
      }
      if (q % 3 == 0) request.set_label(absl::StrCat("c", rng_() % 5));
      CheckSearch(*client, request, query, state, exclude);
    }
  }

  void CheckSearch(const client::IndexerClient& client,
                   const v1::SearchRequest& request,
                   const index::Signature& query,
                   const std::vector<TestModel>& state,
                   const std::string& exclude) {
    ++figures_.verified_searches;
    const client::CallOptions call = CallTimeout();
    std::unique_ptr<client::SearchStream> stream =
        client.Search(request, &call);
    std::vector<v1::Neighbor> got;
    for (v1::Neighbor n; stream->Next(&n);) got.push_back(n);
    const absl::Status status = stream->Finish();
    const std::string what = absl::StrCat(
        "search k=", request.k(),
        request.has_signature() ? " by signature" : " by id ", request.id(),
        request.label().empty() ? "" : " label ", request.label(),
        request.exclude_self() ? " exclude_self" : "");
    if (!status.ok()) {
      figures_.Wrong(absl::StrCat(what, ": ", status.ToString()));
      return;
    }
    // Every acceptable model with its EMD, ascending; ties in distance may
    // come in any order, so each rank is checked by distance and each id by
    // its own EMD.
    const std::vector<Hit> all =
        BruteForce(query, state, static_cast<int>(state.size()), 0,
                   request.label(), exclude);
    std::map<std::string, double> distance_of;
    for (const Hit& h : all) distance_of[h.id] = h.distance;
    const size_t want = std::min(all.size(), static_cast<size_t>(request.k()));
    if (got.size() != want) {
      figures_.Wrong(
          absl::StrCat(what, ": ", got.size(), " results, brute force ", want));
      return;
    }
    std::map<std::string, int> seen;
    for (size_t i = 0; i < got.size(); ++i) {
      const double tol = 1e-9 * (1 + all[i].distance);
      const auto it = distance_of.find(got[i].id());
      if (std::abs(got[i].distance() - all[i].distance) > tol ||
          it == distance_of.end() ||
          std::abs(it->second - got[i].distance()) > tol ||
          ++seen[got[i].id()] > 1) {
        figures_.Wrong(absl::StrFormat(
            "%s: rank %d is %s at %.12g, brute force %s at %.12g", what, i,
            got[i].id(), got[i].distance(), all[i].id, all[i].distance));
        return;
      }
    }
  }

  void Report(double seconds) {
    Figures& f = figures_;
    int64_t ops = 0;
    for (int k = 0; k < kKinds; ++k)
      ops += static_cast<int64_t>(f.latency_ms[k].size());
    std::printf(
        "soak: %.0f s, %lld rounds, %lld kill -9, %lld acknowledged "
        "operations:",
        seconds, static_cast<long long>(f.rounds),
        static_cast<long long>(f.kills), static_cast<long long>(ops));
    for (int k = 0; k < kKinds; ++k) {
      std::printf(" %s %zu%s", kKindNames[k], f.latency_ms[k].size(),
                  k + 1 < kKinds ? "," : "\n");
    }
    std::printf(
        "soak: cut off by a kill %lld (found landed %lld, not landed %lld); "
        "errors with the "
        "server up %lld\n",
        static_cast<long long>(f.failed_at_kill),
        static_cast<long long>(f.resolved_landed),
        static_cast<long long>(f.resolved_not_landed),
        static_cast<long long>(f.unexpected_errors));
    std::printf(
        "soak: verified %lld gets and %lld searches against the oracle\n",
        static_cast<long long>(f.verified_gets),
        static_cast<long long>(f.verified_searches));
    std::printf("soak: losses %lld, phantoms %lld, wrong answers %lld\n",
                static_cast<long long>(f.losses),
                static_cast<long long>(f.phantoms),
                static_cast<long long>(f.wrong_answers));
    for (int k = 0; k < kKinds; ++k) {
      std::printf("soak: %-6s latency p50 %.2f ms, p99 %.2f ms\n",
                  kKindNames[k], Percentile(f.latency_ms[k], 0.50),
                  Percentile(f.latency_ms[k], 0.99));
    }
    std::printf("soak: restart to serving p50 %.3f s, max %.3f s\n",
                Percentile(f.restart_seconds, 0.5),
                Percentile(f.restart_seconds, 1.0));
    std::fflush(stdout);
  }

  const Options options_;
  std::mt19937_64 rng_;
  std::vector<std::unique_ptr<index::testing::SignatureGenerator>> generators_;
  std::vector<Slot> slots_;
  Figures figures_;
};

}  // namespace
}  // namespace tpr::soak

int main(int argc, char** argv) {
  tpr::soak::Options options;
  options.indexer_binary = TPR_SOAK_INDEXER_BINARY;
  CLI::App app{
      "tpr-soak: adds, updates, deletes and searches against a tpr-indexer "
      "that is "
      "killed with SIGKILL at random moments, checked against an in-process "
      "oracle"};
  app.add_option("--indexer", options.indexer_binary, "tpr-indexer binary")
      ->capture_default_str();
  app.add_option("--seconds", options.seconds, "Time bound of the traffic")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--writers", options.writers, "Writer threads")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  app.add_option("--searchers", options.searchers, "Searcher threads")
      ->check(CLI::Range(0, 64))
      ->capture_default_str();
  app.add_option("--ids", options.ids, "Size of the id space")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  app.add_option("--min-run", options.min_run_seconds,
                 "Shortest traffic between kills (s)")
      ->capture_default_str();
  app.add_option("--max-run", options.max_run_seconds,
                 "Longest traffic between kills (s)")
      ->capture_default_str();
  app.add_option("--verify-searches", options.verify_searches,
                 "Searches checked against brute force after each restart")
      ->capture_default_str();
  app.add_option("--seed", options.seed, "Seed of every random choice")
      ->capture_default_str();
  app.add_option("--work-dir", options.work_dir,
                 "Directory for the data and the indexer log (default: a fresh "
                 "one in $TMPDIR)");
  app.add_flag("--keep", options.keep, "Keep the work directory");
  CLI11_PARSE(app, argc, argv);
  if (options.ids < options.writers || options.min_run_seconds <= 0 ||
      options.max_run_seconds < options.min_run_seconds) {
    std::fprintf(stderr,
                 "soak: need ids >= writers and 0 < min-run <= max-run\n");
    return 2;
  }

  std::string work = options.work_dir;
  if (work.empty()) {
    const char* tmp = std::getenv("TMPDIR");
    std::string pattern =
        std::string(tmp != nullptr ? tmp : "/tmp") + "/tpr-soak-XXXXXX";
    if (mkdtemp(pattern.data()) == nullptr) {
      std::perror("soak: mkdtemp");
      return 2;
    }
    work = pattern;
  }
  std::filesystem::create_directories(work);
  signal(SIGINT, tpr::soak::KillChildAndExit);
  signal(SIGTERM, tpr::soak::KillChildAndExit);
  // Watchdog: a hung indexer or client must not hang CI.
  std::thread([limit = options.seconds + 180] {
    std::this_thread::sleep_for(std::chrono::duration<double>(limit));
    std::fprintf(stderr,
                 "soak: still running %.0f s after the start; giving up\n",
                 limit);
    tpr::soak::KillChildAndExit(SIGALRM);
  }).detach();

  const std::string log = work + "/tpr-indexer.log";
  std::printf("soak: %s, data and log in %s\n", options.indexer_binary.c_str(),
              work.c_str());
  int code;
  {
    tpr::soak::IndexerProcess server(options.indexer_binary, work + "/data",
                                     log);
    code = tpr::soak::Soak(options).Run(&server);
  }
  if (code == 0 && !options.keep && options.work_dir.empty()) {
    std::filesystem::remove_all(work);
  } else if (code != 0) {
    std::printf("soak: FAILED; data and indexer log kept in %s\n",
                work.c_str());
  }
  return code;
}
