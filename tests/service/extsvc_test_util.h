// Helpers for the extractor, SDK and CLI service tests: running a service
// binary on a free loopback port, serializing generated meshes as OFF,
// calling the standard health service, converting wire signatures to the
// indexer library's form, and temporary directories.
//
//   ServiceProcess p;
//   ASSERT_TRUE(p.Start(BinaryPath("tpr-extractor"), {}).ok());
//   auto client = tpr::client::ExtractorClient::Connect(p.address());
#ifndef TPR_TESTS_SERVICE_EXTSVC_TEST_UTIL_H_
#define TPR_TESTS_SERVICE_EXTSVC_TEST_UTIL_H_

#include <arpa/inet.h>
#include <grpcpp/channel.h>
#include <grpcpp/client_context.h>
#include <grpcpp/impl/codegen/client_unary_call.h>
#include <grpcpp/impl/codegen/rpc_method.h>
#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/sync_stream.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "extractor/lib/mesh.h"
#include "extractor/synth/synth.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/metric.h"
#include "indexer/lib/signature.h"
#include "indexer/service/convert.h"
#include "tests/service/ops_testing.h"
#include "tpr/v1/signature.pb.h"

namespace tpr::testing {

// BinaryPath returns where the build put executable `name`: the build
// directory itself when CMAKE_RUNTIME_OUTPUT_DIRECTORY gathers them there,
// else the folder of its target (extractor/, indexer/, client/, web/).
inline std::string BinaryPath(const std::string& name) {
  const std::string root = TPR_BINARY_DIR;
  for (const char* sub : {"", "/extractor", "/indexer", "/client", "/web"}) {
    const std::string candidate = root + sub + "/" + name;
    if (access(candidate.c_str(), X_OK) == 0) return candidate;
  }
  return root + "/" + name;
}

// A fresh directory under $TMPDIR, removed with its contents on destruction.
class TempDir {
 public:
  TempDir() {
    std::string pattern =
        (std::filesystem::temp_directory_path() / "tpr-extsvc-test.XXXXXX")
            .string();
    path_ = mkdtemp(pattern.data()) ? pattern : std::string();
  }
  ~TempDir() {
    std::error_code ec;
    if (!path_.empty()) std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// A service binary started with --listen 127.0.0.1:0; the port is read from
// the "(port N)" line that common/server_lifecycle.h logs on stderr.
class ServiceProcess {
 public:
  ~ServiceProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }

  absl::Status Start(const std::string& binary, std::vector<std::string> args,
                     const std::string& log_path,
                     const std::string& listen = "127.0.0.1:0") {
    if (absl::Status s = Launch(binary, std::move(args), log_path, listen);
        !s.ok())
      return s;
    return WaitForPort(binary);
  }

  // Launch starts the process and returns at once, without waiting for the
  // "(port N)" line: for a server that is not expected to serve yet (it
  // listens on `listen`, a fixed address, meanwhile).
  absl::Status Launch(const std::string& binary, std::vector<std::string> args,
                      const std::string& log_path, const std::string& listen) {
    log_path_ = log_path;
    args.insert(args.begin(), binary);
    args.push_back("--listen");
    args.push_back(listen);
    pid_ = fork();
    if (pid_ < 0) return absl::InternalError("fork failed");
    if (pid_ == 0) {
      // Both output streams go to the log: a server left behind by a test
      // that aborted must not hold CTest's output pipe (CTest would wait
      // for it until the test's timeout).
      FILE* log = std::fopen(log_path.c_str(), "w");
      if (log != nullptr) {
        dup2(fileno(log), STDERR_FILENO);
        dup2(fileno(log), STDOUT_FILENO);
      }
      std::vector<char*> argv;
      for (std::string& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    return absl::OkStatus();
  }

 private:
  absl::Status WaitForPort(const std::string& binary) {
    const std::string& log_path = log_path_;
    const auto give_up =
        std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (std::chrono::steady_clock::now() < give_up) {
      std::ifstream in(log_path);
      std::stringstream text;
      text << in.rdbuf();
      const std::string s = text.str();
      const size_t at = s.find("(port ");
      if (at != std::string::npos) {
        port_ = std::atoi(s.c_str() + at + 6);
        if (port_ > 0) return absl::OkStatus();
      }
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        exit_code_ =
            WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        return absl::InternalError(absl::StrCat(binary, " exited early: ", s));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return absl::DeadlineExceededError(
        absl::StrCat(binary, " did not report its port"));
  }

 public:
  // Sends `signo` and waits for the exit; returns the exit code, or 128 +
  // signal when killed by a signal, or -1 after `timeout` (then SIGKILLs).
  int Stop(int signo, std::chrono::seconds timeout = std::chrono::seconds(30)) {
    if (pid_ <= 0) return -1;
    kill(pid_, signo);
    const auto give_up = std::chrono::steady_clock::now() + timeout;
    int status = 0;
    while (std::chrono::steady_clock::now() < give_up) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        if (WIFEXITED(status)) return WEXITSTATUS(status);
        if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
        return -1;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
    return -1;
  }

  // Sends `signo` without waiting (e.g. SIGHUP); returns kill()'s result.
  int Signal(int signo) { return pid_ > 0 ? kill(pid_, signo) : -1; }

  int port() const { return port_; }
  // The exit code (128 + signal when killed) of a process that exited
  // before it reported its port (Start failed), else -1.
  int exit_code() const { return exit_code_; }
  // The process id while running, else -1.
  pid_t pid() const { return pid_; }
  std::string address() const { return absl::StrCat("127.0.0.1:", port_); }
  const std::string& log_path() const { return log_path_; }

 private:
  pid_t pid_ = -1;
  int port_ = 0;
  int exit_code_ = -1;
  std::string log_path_;
};

// OFF text of `mesh` (17 significant digits: the bytes round-trip exactly).
inline std::string ToOff(const extract::Mesh& mesh) {
  std::string out = absl::StrCat("OFF\n", mesh.positions.size(), " ",
                                 mesh.triangles.size(), " 0\n");
  char buffer[128];
  for (const Eigen::Vector3d& p : mesh.positions) {
    std::snprintf(buffer, sizeof(buffer), "%.17g %.17g %.17g\n", p.x(), p.y(),
                  p.z());
    out += buffer;
  }
  for (const auto& t : mesh.triangles)
    absl::StrAppend(&out, "3 ", t[0], " ", t[1], " ", t[2], "\n");
  return out;
}

inline void WriteFile(const std::string& path, const std::string& bytes) {
  std::filesystem::create_directories(
      std::filesystem::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << bytes;
}

// Calls grpc.health.v1.Health/Check for the overall server (""); see
// HealthStatus (tests/service/ops_testing.h). Any failure is UNAVAILABLE.
inline absl::StatusOr<int> HealthCheck(
    const std::shared_ptr<grpc::Channel>& channel) {
  absl::StatusOr<int> status = HealthStatus(channel, "");
  if (!status.ok()) return absl::UnavailableError(status.status().message());
  return status;
}

// RawClientStream calls client-streaming `method` ("/tpr.v1.Indexer/
// BatchUpsert") with each of `messages` sent as raw bytes, as a client in
// another language (or a fuzzer) could; returns the call's status and the
// response's bytes in *response (when given). A Write the server no longer
// reads is ignored: the status tells what happened.
inline grpc::Status RawClientStream(
    const std::shared_ptr<grpc::Channel>& channel, const std::string& method,
    const std::vector<std::string>& messages, std::string* response = nullptr) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(30));
  grpc::ByteBuffer answer;
  const grpc::internal::RpcMethod rpc(
      method.c_str(), grpc::internal::RpcMethod::CLIENT_STREAMING);
  std::unique_ptr<grpc::ClientWriter<grpc::ByteBuffer>> writer(
      grpc::internal::ClientWriterFactory<grpc::ByteBuffer>::Create(
          channel.get(), rpc, &context, &answer));
  for (const std::string& bytes : messages) {
    grpc::Slice slice(bytes.data(), bytes.size());
    grpc::ByteBuffer request(&slice, 1);
    if (!writer->Write(request)) break;
  }
  writer->WritesDone();
  grpc::Status status = writer->Finish();
  if (response != nullptr) {
    response->clear();
    std::vector<grpc::Slice> slices;
    if (status.ok() && answer.Dump(&slices).ok()) {
      for (const grpc::Slice& s : slices) {
        response->append(reinterpret_cast<const char*>(s.begin()), s.size());
      }
    }
  }
  return status;
}

// FreePort returns a loopback TCP port that was free a moment ago.
inline int FreePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  socklen_t len = sizeof(addr);
  int port = 0;
  if (bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0) {
    port = ntohs(addr.sin_port);
  }
  close(fd);
  return port;
}

// A generated labelled set on disk: <dir>/<class>/pose_<i>.off.
struct GeneratedFile {
  std::string relative_path;  // "<class>/pose_<i>.off", the id `tpr add` gives
  std::string label;
  std::string off;
};

inline absl::StatusOr<std::vector<GeneratedFile>> GenerateSet(
    const std::string& dir, int classes, int poses, int vertices) {
  std::vector<GeneratedFile> files;
  const std::vector<std::string> names = synth::ClassNames();
  if (classes > static_cast<int>(names.size())) {
    return absl::InvalidArgumentError("not that many synthetic classes");
  }
  for (int c = 0; c < classes; ++c) {
    for (int p = 0; p < poses; ++p) {
      synth::ShapeOptions options;
      options.target_vertices = vertices;
      options.seed = 11;
      absl::StatusOr<extract::Mesh> mesh =
          synth::GenerateShape(names[c], p, options);
      if (!mesh.ok()) return mesh.status();
      GeneratedFile f;
      f.relative_path = absl::StrCat(names[c], "/pose_", p, ".off");
      f.label = names[c];
      f.off = ToOff(*mesh);
      WriteFile(dir + "/" + f.relative_path, f.off);
      files.push_back(std::move(f));
    }
  }
  return files;
}

// Both services as real processes on free loopback ports.
class Cluster {
 public:
  absl::Status Start(int extractors = 1) {
    if (dir_.path().empty()) return absl::InternalError("no temp dir");
    extractors_.resize(extractors);
    for (int i = 0; i < extractors; ++i) {
      extractors_[i] = std::make_unique<ServiceProcess>();
      absl::Status s = extractors_[i]->Start(
          BinaryPath("tpr-extractor"), {"--threads", "2"},
          absl::StrCat(dir_.path(), "/extractor", i, ".log"));
      if (!s.ok()) return s;
    }
    return indexer_.Start(BinaryPath("tpr-indexer"),
                          {"--data-dir", dir_.path() + "/data"},
                          dir_.path() + "/indexer.log");
  }
  std::string extractor_addresses() const {
    std::string out;
    for (const auto& e : extractors_)
      absl::StrAppend(&out, out.empty() ? "" : ",", e->address());
    return out;
  }
  ServiceProcess& extractor(int i) { return *extractors_[i]; }
  ServiceProcess& indexer() { return indexer_; }
  const std::string& dir() const { return dir_.path(); }

 private:
  TempDir dir_;
  std::vector<std::unique_ptr<ServiceProcess>> extractors_;
  ServiceProcess indexer_;
};

// One entry of a brute-force ranking.
struct Ranked {
  double distance;
  std::string id;
};

// BruteForceRanking returns every model of `models` (id -> signature) ranked
// by exact distance (indexer/lib/metric.h under the default intent's
// weighting, default options, which the indexer uses) to `query`,
// ascending, ties by id. The oracle the services' VP-tree answers are
// compared with. `distance` replaces that distance (e.g. index::Emd alone,
// for SearchRequest.ranking, or another intent's weighting).
inline absl::StatusOr<std::vector<Ranked>> BruteForceRanking(
    const v1::Signature& query,
    const std::vector<std::pair<std::string, v1::Signature>>& models,
    const std::function<double(const index::PreparedSignature&,
                               const index::PreparedSignature&)>& distance =
        [](const index::PreparedSignature& a,
           const index::PreparedSignature& b) {
          return index::Distance(
              a, b, index::IntentWeights(index::Intent::kBalanced));
        }) {
  const index::GroundDistanceOptions options;
  absl::StatusOr<index::Signature> query_signature =
      indexer::ToIndexSignature(query);
  if (!query_signature.ok()) return query_signature.status();
  absl::StatusOr<index::PreparedSignature> q =
      index::Prepare(*query_signature, options);
  if (!q.ok()) return q.status();
  std::vector<Ranked> ranked;
  for (const auto& [id, signature] : models) {
    absl::StatusOr<index::Signature> model_signature =
        indexer::ToIndexSignature(signature);
    if (!model_signature.ok()) return model_signature.status();
    absl::StatusOr<index::PreparedSignature> m =
        index::Prepare(*model_signature, options);
    if (!m.ok()) return m.status();
    ranked.push_back({distance(*q, *m), id});
  }
  std::sort(ranked.begin(), ranked.end(), [](const Ranked& a, const Ranked& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.id < b.id;
  });
  return ranked;
}

// SameRanking returns "" when `got` (as streamed) equals the first
// got.size() entries of `expected`: same distances (1e-9 relative), same ids
// except that models at equal distance may come in either order; otherwise a
// description of the first difference.
inline std::string SameRanking(const std::vector<Ranked>& got,
                               const std::vector<Ranked>& expected) {
  if (got.size() > expected.size()) return "more results than models";
  auto close = [](double a, double b) {
    return std::abs(a - b) <= 1e-9 * (1.0 + std::abs(b));
  };
  for (size_t r = 0; r < got.size(); ++r) {
    if (!close(got[r].distance, expected[r].distance)) {
      return absl::StrCat("rank ", r + 1, ": distance ", got[r].distance, " (",
                          got[r].id, ") vs brute force ", expected[r].distance,
                          " (", expected[r].id, ")");
    }
    if (got[r].id == expected[r].id) continue;
    bool tied = false;
    for (const Ranked& e : expected) {
      if (e.id == got[r].id && close(e.distance, expected[r].distance))
        tied = true;
    }
    if (!tied) {
      return absl::StrCat("rank ", r + 1, ": ", got[r].id, " vs brute force ",
                          expected[r].id);
    }
  }
  return "";
}

// CommandResult: what one run of the `tpr` command printed and returned.
struct CommandResult {
  int exit_code = -1;
  std::string out;
  std::string err;
};

// RunTpr runs `tpr ARGS` against `cluster` (addresses through the
// environment, as a user sets them) and captures stdout and stderr.
inline CommandResult RunTpr(Cluster& cluster, const std::string& args) {
  const std::string err_path = cluster.dir() + "/tpr.stderr";
  const std::string command =
      absl::StrCat("TPR_EXTRACTOR=", cluster.extractor_addresses(),
                   " TPR_INDEXER=", cluster.indexer().address(), " ",
                   BinaryPath("tpr"), " ", args, " 2>", err_path);
  const ShellResult run = RunCommand(command);
  CommandResult result;
  result.exit_code = run.exit_code;
  result.out = run.out;
  result.err = ReadText(err_path);
  return result;
}

}  // namespace tpr::testing

#endif  // TPR_TESTS_SERVICE_EXTSVC_TEST_UTIL_H_
