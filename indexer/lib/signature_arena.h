// SignatureArena: an index's prepared signatures in one contiguous,
// huge-page-advised block, laid out in the VP-tree's order.
//
// A search over 1M models bounds about 15,600 cold signatures of 3.5 KB per
// 10-NN query at level 2 (docs/search-cost.md). With one heap block per
// signature on 4 KB pages, each is also a TLB miss and a page walk; and a
// bucket's items, which a search bounds together, lie wherever malloc put
// them. The arena copies every block into one mapping advised for 2 MiB
// pages (huge_pages.h), in VpTree::ItemsInTreeOrder, so that a bucket's
// signatures are adjacent (a 128-item bucket of 3.5 KB signatures spans at
// most two huge pages) and a subtree's buckets near each other. The views
// (PreparedSignature::CopyInto) sit in one flat array indexed by item, so
// an item costs no separate heap object or shared_ptr control block.
//
//   SignatureArena arena = SignatureArena::Build(
//       items.size(), tree.ItemsInTreeOrder(),
//       [&](uint32_t i) { return &items[i]; });
//   const PreparedSignature* p = arena.get(i);   // nullptr: absent
//   double d = Distance(query, *p);              // as on the original
#ifndef TPR_INDEXER_LIB_SIGNATURE_ARENA_H_
#define TPR_INDEXER_LIB_SIGNATURE_ARENA_H_

#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "indexer/lib/ground_distance.h"
#include "indexer/lib/huge_pages.h"

namespace tpr::index {

// SignatureArena holds, for slots 0 .. size() - 1, a copy of one prepared
// signature (or nothing: an absent slot). Immutable once built; movable,
// not copyable (views point into its storage, which a move keeps in
// place); thread-safe to read from any number of threads.
class SignatureArena {
 public:
  SignatureArena() = default;
  SignatureArena(SignatureArena&&) noexcept = default;
  SignatureArena& operator=(SignatureArena&&) noexcept = default;
  SignatureArena(const SignatureArena&) = delete;
  SignatureArena& operator=(const SignatureArena&) = delete;

  // Build returns the arena of `n` slots: slot i holds a copy of *item(i)
  // (equal values and serial(); nothing for nullptr). Blocks are placed
  // in the order of `order`, then any slot `order` does not name in slot
  // order; slots named twice or >= n in `order` are ignored. item is called
  // once or twice per slot from the calling thread, and what it returns
  // must stay valid during the call. Cost: O(n + total block bytes) time
  // and the blocks' bytes (each rounded up to 8) plus 32 B per slot.
  static SignatureArena Build(
      size_t n, const std::vector<uint32_t>& order,
      const std::function<const PreparedSignature*(uint32_t)>& item);

  // size returns the number of slots.
  size_t size() const { return views_.size(); }
  // get returns slot i's signature, nullptr for an absent slot. Valid while
  // the arena lives. Precondition: i < size(). O(1).
  const PreparedSignature* get(uint32_t i) const {
    const PreparedSignature& p = views_[i];
    return p.size() == 0 ? nullptr : &p;
  }
  // operator[] is *get(i) for a present slot i. O(1).
  const PreparedSignature& operator[](size_t i) const { return views_[i]; }
  // MemoryBytes returns the bytes the arena holds: blocks and views.
  size_t MemoryBytes() const {
    return storage_.capacity() + views_.capacity() * sizeof(PreparedSignature);
  }

 private:
  HugeVector<std::byte> storage_;
  HugeVector<PreparedSignature> views_;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_SIGNATURE_ARENA_H_
