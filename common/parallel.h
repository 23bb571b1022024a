// A small parallel loop over indices with dynamic scheduling: the one used
// by the extraction (per-thread Dijkstra solvers), the evaluation (distance
// matrices, extraction) and the `tpr` command (parallel uploads and
// queries). Header-only and free of gRPC, so the pure libraries may include
// it (tests/check_layering.cmake). Written by hand: the needs are one
// function and no pool that outlives the call; std::execution needs TBB at
// link time on GCC 12 and OpenMP gives no per-worker set-up. (The indexer's
// search keeps a oneTBB arena for its lifetime instead: microsecond
// dispatch of a few EMDs, indexer/lib/signature_index.cc.)
//
//   ParallelFor(items.size(), 4, [&](size_t i) { Process(items[i]); });
//   ParallelForEachWorker(n, 4, [] { Solver s; return [s](size_t i) mutable
//                                    { s.Run(i); }; });
#ifndef TPR_COMMON_PARALLEL_H_
#define TPR_COMMON_PARALLEL_H_

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace tpr::common {

// ParallelForEachWorker runs fn(i) for every i in [0, n) on
// min(max(1, threads), max(1, n)) threads. Each worker first calls
// make_worker() once to get its own `fn` (so it owns its scratch, e.g. a
// solver), then takes the next free index until none is left, so that slow
// items do not hold up a fixed share. Returns when all are done.
// `make_worker` must be thread-safe; each `fn` is used by one thread only.
template <typename MakeWorker>
void ParallelForEachWorker(size_t n, int threads, MakeWorker make_worker) {
  std::atomic<size_t> next{0};
  const size_t count =
      std::min<size_t>(std::max(1, threads), std::max<size_t>(1, n));
  std::vector<std::thread> pool;
  pool.reserve(count);
  for (size_t t = 0; t < count; ++t) {
    pool.emplace_back([&] {
      auto fn = make_worker();
      for (size_t i = next++; i < n; i = next++) fn(i);
    });
  }
  for (std::thread& t : pool) t.join();
}

// ParallelFor runs fn(i) for every i in [0, n) as ParallelForEachWorker,
// every worker sharing `fn`, which must be thread-safe.
template <typename Fn>
void ParallelFor(size_t n, int threads, const Fn& fn) {
  ParallelForEachWorker(n, threads,
                        [&fn] { return [&fn](size_t i) { fn(i); }; });
}

}  // namespace tpr::common

#endif  // TPR_COMMON_PARALLEL_H_
