// Huge pages for the index's large arrays (10-NN over 1M models).
//
// A search over 1M models touches about 15,600 cold signatures of 3.5 KB,
// 20,700 centroid rows and the stored distances of about 30,000 bucket
// items per query, spread over 4 GB. On 4 KB pages nearly every one of
// those reads also misses the TLB and walks the page table; on 2 MiB pages
// the TLB covers far more of the index (docs/search-cost.md measured
// 51.0 -> 43.1 ms at 1M with glibc's `glibc.malloc.hugetlb=1`, which
// advises the whole heap). Where transparent huge pages are enabled only
// for advised memory (`madvise` in /sys/kernel/mm/transparent_hugepage/
// enabled, the default of many distributions), memory must ask for them
// itself: these helpers map large allocations privately and advise them
// MADV_HUGEPAGE, so the index gets huge pages without any environment
// setting. Where THP is off or absent the advice is ignored and the memory
// is ordinary; nothing depends on it but speed.
//
//   std::vector<double, HugePageAllocator<double>> big(1 << 24);
//   // backed by 2 MiB pages where the kernel grants them
#ifndef TPR_INDEXER_LIB_HUGE_PAGES_H_
#define TPR_INDEXER_LIB_HUGE_PAGES_H_

#include <cstddef>
#include <new>
#include <vector>

namespace tpr::index {

// kHugePageAdviceBytes: allocations of at least this many bytes are mapped
// and advised for huge pages (one x86-64 huge page: a smaller region
// cannot hold one); smaller ones come from operator new.
inline constexpr size_t kHugePageAdviceBytes = size_t{2} << 20;

// AllocateLarge returns `bytes` (> 0) of zero-filled memory aligned to at
// least 4096 bytes, from a private anonymous mapping of `bytes` rounded up
// to whole 4 KB pages, advised MADV_HUGEPAGE where the platform has it (the
// kernel backs every 2 MiB-aligned 2 MiB range inside it with a huge page
// when it can; the head and tail stay 4 KB pages, so no more than the
// rounded size is ever resident). Throws std::bad_alloc when the mapping
// fails (as operator new would). Release with FreeLarge(p, bytes), the same
// `bytes`. Cost: one mmap and one madvise call; pages are faulted in on
// first touch. Thread-safe.
void* AllocateLarge(size_t bytes);

// FreeLarge unmaps memory from AllocateLarge(bytes); no-op for nullptr.
// Thread-safe.
void FreeLarge(void* p, size_t bytes) noexcept;

// HugePageAllocator: a standard allocator that serves requests of at least
// kHugePageAdviceBytes from AllocateLarge and smaller ones from operator
// new, for the index's big flat arrays (std::vector<T, HugePageAllocator<T>>).
// Stateless: every instance can free what any other allocated. For T with
// alignof(T) <= alignof(std::max_align_t). Thread-safe.
template <typename T>
struct HugePageAllocator {
  using value_type = T;

  HugePageAllocator() noexcept = default;
  template <typename U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}  // NOLINT

  T* allocate(size_t n) {
    if (n > static_cast<size_t>(-1) / sizeof(T)) throw std::bad_alloc();
    const size_t bytes = n * sizeof(T);
    if (bytes >= kHugePageAdviceBytes) {
      return static_cast<T*>(AllocateLarge(bytes));
    }
    return static_cast<T*>(::operator new(bytes));
  }
  void deallocate(T* p, size_t n) noexcept {
    const size_t bytes = n * sizeof(T);
    if (bytes >= kHugePageAdviceBytes) {
      FreeLarge(p, bytes);
    } else {
      ::operator delete(p);
    }
  }

  friend bool operator==(const HugePageAllocator&,
                         const HugePageAllocator&) noexcept {
    return true;
  }
  friend bool operator!=(const HugePageAllocator&,
                         const HugePageAllocator&) noexcept {
    return false;
  }
};

// HugeVector: a std::vector whose buffer, once 2 MiB or more, is advised
// for huge pages (HugePageAllocator).
template <typename T>
using HugeVector = std::vector<T, HugePageAllocator<T>>;

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_HUGE_PAGES_H_
