// Extraction throughput of one tpr-extractor (in-process ExtractorService on
// a loopback port, 2 worker threads) against the same work done in-process
// by 2 threads, so that the ratio (the cost of gRPC, chunked upload and
// conversion) holds on a noisy machine. Meshes: a synthetic biped at the
// given vertex count, sent as OFF text.
//
//   bench_extractor_service --benchmark_filter='/10000/'
//       --benchmark_repetitions=3
#include <benchmark/benchmark.h>

#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "common/server_lifecycle.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/service/extractor_service.h"
#include "extractor/synth/synth.h"
#include "tests/service/extsvc_test_util.h"
#include "tpr/client.h"

namespace tpr::extractor {
namespace {

const std::string& MeshOff(int vertices) {
  static std::mutex mu;
  static std::map<int, std::string>* cache = new std::map<int, std::string>;
  std::lock_guard<std::mutex> lock(mu);
  auto it = cache->find(vertices);
  if (it == cache->end()) {
    synth::ShapeOptions options;
    options.target_vertices = vertices;
    options.seed = 3;
    absl::StatusOr<extract::Mesh> mesh =
        synth::GenerateShape("biped_adult", 1, options);
    it = cache
             ->emplace(vertices,
                       mesh.ok() ? testing::ToOff(*mesh) : std::string())
             .first;
  }
  return it->second;
}

// One server for the whole run (never destroyed: benchmarks exit after).
const std::string& ServerAddress() {
  static const std::string* address = [] {
    extractor::ServiceOptions options;
    options.worker_threads = 2;
    auto* service = new extractor::ExtractorService(options);
    common::ServerOptions server_options;
    server_options.listen_address = "127.0.0.1:0";
    absl::StatusOr<common::StartedServer> started =
        common::StartServer(server_options, {service});
    if (!started.ok()) return new std::string();
    auto* port = new int(started->port);
    started->server.release();  // leaked on purpose, see above
    return new std::string(absl::StrCat("127.0.0.1:", *port));
  }();
  return *address;
}

// Callers = benchmark threads, each streaming the mesh and waiting for the
// signature; the server runs at most 2 extractions at once, the rest queue.
void BM_ExtractorService(benchmark::State& state) {
  const std::string& off = MeshOff(static_cast<int>(state.range(0)));
  absl::StatusOr<client::ExtractorClient> client =
      client::ExtractorClient::Connect(ServerAddress());
  if (!client.ok() || off.empty()) {
    state.SkipWithError("no server or mesh");
    return;
  }
  for (auto _ : state) {
    absl::StatusOr<v1::ExtractResponse> r =
        client->ExtractBytes(off, "biped.off");
    if (!r.ok()) {
      state.SkipWithError(r.status().ToString().c_str());
      return;
    }
    benchmark::DoNotOptimize(r->signature().features_size());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ExtractorService)
    ->Arg(2000)
    ->Arg(10000)
    ->Threads(4)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

// The peer: intake + extraction in-process on 2 threads, no gRPC.
void BM_ExtractInProcess(benchmark::State& state) {
  const std::string& off = MeshOff(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    absl::StatusOr<extract::LoadedMesh> loaded = extract::LoadMeshFromBuffer(
        off, extract::MeshFormat::kOff, "biped.off", {});
    if (!loaded.ok()) {
      state.SkipWithError(loaded.status().ToString().c_str());
      return;
    }
    absl::StatusOr<extract::ExtractResult> r = extract::ExtractSignature(
        loaded->mesh, loaded->stats, extract::Options{});
    if (!r.ok()) {
      state.SkipWithError(r.status().ToString().c_str());
      return;
    }
    benchmark::DoNotOptimize(r->signature.features.size());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ExtractInProcess)
    ->Arg(2000)
    ->Arg(10000)
    ->Threads(2)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace tpr::extractor

BENCHMARK_MAIN();
