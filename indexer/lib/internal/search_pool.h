// SignatureIndex::SearchPool, the threads of one index's intra-query
// parallelism (IndexOptions::search_threads). Internal to indexer/lib:
// only signature_index.cc includes it.
#ifndef TPR_INDEXER_LIB_INTERNAL_SEARCH_POOL_H_
#define TPR_INDEXER_LIB_INTERNAL_SEARCH_POOL_H_

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <functional>
#include <thread>
#include <vector>

#include "indexer/lib/signature_index.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"
#include "tbb/task_arena.h"

namespace tpr::index {

// A oneTBB task arena of IndexOptions::search_threads threads. Why oneTBB:
// a search step hands out 2 to 8 EMDs of about 20 us each, so a pool must
// dispatch in a few microseconds and let the calling thread take part;
// task_arena does both, is safe to enter from many threads at once, and
// keeps its workers for the index's lifetime.
#if defined(__SANITIZE_THREAD__)
#define TPR_THREAD_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define TPR_THREAD_SANITIZER 1
#endif
#endif
#ifndef TPR_THREAD_SANITIZER
struct SignatureIndex::SearchPool {
  explicit SearchPool(int threads) : arena(threads) {}
  void ParallelFor(size_t n, const std::function<void(size_t)>& body) {
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1),
                        [&](const tbb::blocked_range<size_t>& r) {
                          for (size_t i = r.begin(); i != r.end(); ++i) body(i);
                        });
    });
  }
  tbb::task_arena arena;
};
#else
// ThreadSanitizer builds (-DTPR_SANITIZE=thread): Debian's libtbb is not
// instrumented, so TSan cannot see it hand a task to another thread and
// reports every task (TBB's own fields and everything our bodies read) as
// a race. These builds run the same bodies on plain threads, joined before
// returning, which TSan does see: it then checks the bodies and what they
// share, which is what is ours.
struct SignatureIndex::SearchPool {
  explicit SearchPool(int threads)
      : threads(static_cast<size_t>(std::max(threads, 1))) {}
  void ParallelFor(size_t n, const std::function<void(size_t)>& body) {
    std::atomic<size_t> next{0};
    auto work = [&] {
      for (size_t i = next++; i < n; i = next++) body(i);
    };
    std::vector<std::thread> helpers;
    for (size_t t = 1; t < std::min(n, threads); ++t)
      helpers.emplace_back(work);
    work();
    for (std::thread& t : helpers) t.join();
  }
  size_t threads;
};
#endif

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_INTERNAL_SEARCH_POOL_H_
