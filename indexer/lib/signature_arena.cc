// SignatureArena (signature_arena.h): two passes over the slots, one to size
// the storage, one to copy each block to its place.
#include "indexer/lib/signature_arena.h"

#include <cassert>

namespace tpr::index {

namespace {

// Each block starts 8-aligned (its masses are doubles).
size_t Rounded(size_t bytes) { return (bytes + 7) / 8 * 8; }

}  // namespace

SignatureArena SignatureArena::Build(
    size_t n, const std::vector<uint32_t>& order,
    const std::function<const PreparedSignature*(uint32_t)>& item) {
  // The placement: `order` first (valid, first mention), then the rest.
  std::vector<uint32_t> placement;
  placement.reserve(n);
  std::vector<bool> placed(n, false);
  for (uint32_t i : order) {
    if (i < n && !placed[i]) {
      placed[i] = true;
      placement.push_back(i);
    }
  }
  for (uint32_t i = 0; i < n; ++i) {
    if (!placed[i]) placement.push_back(i);
  }
  std::vector<size_t> offset(n, 0);
  size_t total = 0;
  for (uint32_t i : placement) {
    if (const PreparedSignature* p = item(i); p != nullptr && p->size() > 0) {
      offset[i] = total;
      total += Rounded(p->MemoryBytes());
    }
  }
  SignatureArena arena;
  arena.storage_.resize(total);
  arena.views_.resize(n);
  for (uint32_t i : placement) {
    if (const PreparedSignature* p = item(i); p != nullptr && p->size() > 0) {
      assert(offset[i] + p->MemoryBytes() <= total);
      arena.views_[i] = p->CopyInto(arena.storage_.data() + offset[i]);
    }
  }
  return arena;
}

}  // namespace tpr::index
