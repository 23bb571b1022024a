// Large, huge-page-advised allocations (huge_pages.h). Why by hand: the
// C++ and absl allocators have no huge-page mode, glibc's only one is an
// environment tunable for the whole process (glibc.malloc.hugetlb), and
// jemalloc/tcmalloc would replace the allocator of every process linking
// the library; two system calls do the job for the few large arrays.
#include "indexer/lib/huge_pages.h"

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

#include <cstdlib>
#include <cstring>

namespace tpr::index {

namespace {

constexpr size_t kSmallPage = 4096;

size_t RoundToPages(size_t bytes) {
  return (bytes + kSmallPage - 1) / kSmallPage * kSmallPage;
}

}  // namespace

#if defined(__linux__)

void* AllocateLarge(size_t bytes) {
  const size_t mapped = RoundToPages(bytes);
  void* p = mmap(nullptr, mapped, PROT_READ | PROT_WRITE,
                 MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) throw std::bad_alloc();
#if defined(MADV_HUGEPAGE)
  // Advice only: EINVAL where THP is compiled out changes nothing else.
  (void)madvise(p, mapped, MADV_HUGEPAGE);
#endif
  return p;
}

void FreeLarge(void* p, size_t bytes) noexcept {
  if (p != nullptr) munmap(p, RoundToPages(bytes));
}

#else  // no mmap: ordinary, page-aligned memory

void* AllocateLarge(size_t bytes) {
  void* p = std::aligned_alloc(kSmallPage, RoundToPages(bytes));
  if (p == nullptr) throw std::bad_alloc();
  std::memset(p, 0, RoundToPages(bytes));
  return p;
}

void FreeLarge(void* p, size_t) noexcept { std::free(p); }

#endif

}  // namespace tpr::index
