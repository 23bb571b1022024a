// Counts heap allocations, to check that warmed-up solvers reuse their
// buffers (Dijkstra sweeps, the EMD). Replacing the global operators is
// allowed by the standard; include this header in exactly one translation
// unit of a test binary.
//
//   const int64_t before = tpr::testing::Allocations();
//   solver.Run(source);
//   EXPECT_EQ(tpr::testing::Allocations(), before);
#ifndef TPR_TESTS_ALLOCATION_COUNTER_H_
#define TPR_TESTS_ALLOCATION_COUNTER_H_

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>

// GCC cannot see that these replacements pair malloc with free.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

namespace tpr::testing {
inline std::atomic<int64_t> g_allocations{0};
// Allocations returns the number of operator new calls so far.
inline int64_t Allocations() { return g_allocations.load(); }
}  // namespace tpr::testing

void* operator new(std::size_t size) {
  tpr::testing::g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

#endif  // TPR_TESTS_ALLOCATION_COUNTER_H_
