// SignatureArena and its parts (huge_pages.h, PreparedSignature::CopyInto,
// VpTree::ItemsInTreeOrder) against their oracles: the arena's views must
// be bit-for-bit the signatures they copy (every stored value, the serial,
// every distance and bound computed from them), absent slots absent, and
// the blocks placed in the order asked for; a copy of a view must own its
// block; large HugeVector buffers must be advised for huge pages where the
// kernel has transparent huge pages; the tree order must list every item
// once, neighbours in the tree adjacent.
#include "indexer/lib/signature_arena.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/huge_pages.h"
#include "indexer/lib/metric.h"
#include "indexer/lib/vp_tree.h"
#include "tests/indexer/signature_testing.h"
#include "tests/sanitizers/sanitizer_build.h"

namespace tpr::index {
namespace {

using testing::SignatureGenerator;
using testing::SignatureGeneratorOptions;

std::vector<PreparedSignature> Draw(int count, uint64_t seed) {
  SignatureGeneratorOptions o;
  o.seed = seed;
  o.classes = 4;
  o.spectrum = 30;  // so that the spectral embedding is stored too
  SignatureGenerator gen(o);
  std::vector<PreparedSignature> out;
  for (int i = 0; i < count; ++i) {
    absl::StatusOr<PreparedSignature> p =
        Prepare(gen.Next(), GroundDistanceOptions{});
    EXPECT_TRUE(p.ok()) << p.status();
    out.push_back(*std::move(p));
  }
  return out;
}

// ExpectSameSignature: equal shape and serial, every stored byte equal.
void ExpectSameSignature(const PreparedSignature& a,
                         const PreparedSignature& b) {
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(a.bands(), b.bands());
  ASSERT_EQ(a.spectral_size(), b.spectral_size());
  ASSERT_EQ(a.heat_size(), b.heat_size());
  EXPECT_EQ(a.serial(), b.serial());
  ASSERT_EQ(a.MemoryBytes(), b.MemoryBytes());
  EXPECT_EQ(std::memcmp(a.weights(), b.weights(), a.MemoryBytes()), 0);
}

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST(SignatureArenaTest, ViewsEqualTheOriginalsBitForBit) {
  const std::vector<PreparedSignature> items = Draw(40, 3);
  const std::vector<PreparedSignature> queries = Draw(5, 4);
  std::vector<uint32_t> order(items.size());
  std::iota(order.begin(), order.end(), 0u);
  std::reverse(order.begin(), order.end());
  // Every fifth slot absent.
  const SignatureArena arena = SignatureArena::Build(
      items.size(), order, [&](uint32_t i) -> const PreparedSignature* {
        return i % 5 == 2 ? nullptr : &items[i];
      });
  ASSERT_EQ(arena.size(), items.size());
  for (uint32_t i = 0; i < items.size(); ++i) {
    const PreparedSignature* v = arena.get(i);
    if (i % 5 == 2) {
      EXPECT_EQ(v, nullptr) << i;
      continue;
    }
    ASSERT_NE(v, nullptr) << i;
    EXPECT_FALSE(v->owns_block());
    ExpectSameSignature(*v, items[i]);
    for (const PreparedSignature& q : queries) {
      const TermWeights all{1, 1, 1};  // every term
      EXPECT_TRUE(SameBits(Distance(q, *v, all), Distance(q, items[i], all)))
          << i;
      EXPECT_TRUE(SameBits(ConstrainedTransportBound32(q, *v),
                           ConstrainedTransportBound32(q, items[i])))
          << i;
      EXPECT_TRUE(SameBits(EmdLowerBound(q, *v), EmdLowerBound(q, items[i])))
          << i;
    }
  }
}

TEST(SignatureArenaTest, BlocksFollowTheOrderThenTheRest) {
  const std::vector<PreparedSignature> items = Draw(12, 5);
  // Out of range and repeated entries are ignored; 0, 1, 2 and 11 are not
  // named and follow in slot order.
  const std::vector<uint32_t> order = {9, 4, 4, 7, 100, 3, 10, 8, 6, 5, 9};
  const SignatureArena arena = SignatureArena::Build(
      items.size(), order, [&](uint32_t i) { return &items[i]; });
  const std::vector<uint32_t> placement = {9, 4, 7, 3, 10, 8,
                                           6, 5, 0, 1, 2,  11};
  for (size_t k = 0; k + 1 < placement.size(); ++k) {
    const PreparedSignature& a = arena[placement[k]];
    const PreparedSignature& b = arena[placement[k + 1]];
    const auto* end_a =
        reinterpret_cast<const std::byte*>(a.weights()) + a.MemoryBytes();
    const auto* begin_b = reinterpret_cast<const std::byte*>(b.weights());
    // Adjacent: b starts at a's end rounded up to 8 bytes.
    EXPECT_GE(begin_b, end_a) << k;
    EXPECT_LT(begin_b, end_a + 8) << k;
    EXPECT_EQ(reinterpret_cast<uintptr_t>(begin_b) % alignof(double), 0u);
  }
  size_t blocks = 0;
  for (const PreparedSignature& p : items)
    blocks += (p.MemoryBytes() + 7) / 8 * 8;
  EXPECT_GE(arena.MemoryBytes(),
            blocks + items.size() * sizeof(PreparedSignature));
}

TEST(SignatureArenaTest, CopiesOfViewsOwnTheirBlockAndOutliveTheArena) {
  const std::vector<PreparedSignature> items = Draw(6, 6);
  std::vector<PreparedSignature> copies;
  {
    SignatureArena arena = SignatureArena::Build(
        items.size(), {}, [&](uint32_t i) { return &items[i]; });
    SignatureArena moved = std::move(arena);  // views stay valid
    for (uint32_t i = 0; i < items.size(); ++i) {
      PreparedSignature copy = moved[i];
      EXPECT_TRUE(copy.owns_block());
      EXPECT_NE(copy.weights(), moved[i].weights());
      copies.push_back(std::move(copy));
    }
  }
  for (uint32_t i = 0; i < items.size(); ++i) {
    ExpectSameSignature(copies[i], items[i]);
    EXPECT_TRUE(SameBits(Distance(items[0], copies[i], TermWeights{1, 1, 1}),
                         Distance(items[0], items[i], TermWeights{1, 1, 1})));
  }
}

TEST(SignatureArenaTest, MovesCarryOwnership) {
  std::vector<PreparedSignature> items = Draw(2, 7);
  std::vector<std::byte> storage(items[0].MemoryBytes() + 8);
  // std::vector<std::byte> storage from operator new: aligned for double.
  PreparedSignature view = items[0].CopyInto(storage.data());
  EXPECT_FALSE(view.owns_block());
  PreparedSignature owner = std::move(items[1]);
  EXPECT_TRUE(owner.owns_block());
  EXPECT_EQ(items[1].size(), 0);
  EXPECT_FALSE(items[1].owns_block());
  // Assigning a view over an owner frees the owner's block (ASan checks
  // the leak) and takes the view's non-ownership.
  owner = std::move(view);
  EXPECT_FALSE(owner.owns_block());
  EXPECT_EQ(owner.weights(), reinterpret_cast<const double*>(storage.data()));
  ExpectSameSignature(owner, items[0]);
}

// The VmFlags line of the mapping of /proc/self/smaps holding `p`, or "".
std::string VmFlagsOf(const void* p) {
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  const uintptr_t at = reinterpret_cast<uintptr_t>(p);
  while (std::getline(smaps, line)) {
    uintptr_t begin = 0;
    uintptr_t end = 0;
    char dash = 0;
    std::istringstream head(line);
    if (head >> std::hex >> begin >> dash >> end && dash == '-') {
      inside = begin <= at && at < end;
      continue;
    }
    if (inside && line.rfind("VmFlags:", 0) == 0) return line;
  }
  return "";
}

TEST(HugePagesTest, LargeBuffersAreAdvisedSmallOnesAreNot) {
  HugeVector<double> large(kHugePageAdviceBytes / sizeof(double) + 1, 1.5);
  HugeVector<double> small(1000, 2.5);
  EXPECT_EQ(std::count(large.begin(), large.end(), 1.5),
            static_cast<ptrdiff_t>(large.size()));
  EXPECT_EQ(std::count(small.begin(), small.end(), 2.5), 1000);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(large.data()) % 4096, 0u);
  std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
  const std::string flags = VmFlagsOf(large.data());
  if (!thp || flags.empty()) {
    GTEST_SKIP() << "no transparent huge pages or no /proc/self/smaps here";
  }
  // "hg": the mapping carries MADV_HUGEPAGE.
  EXPECT_NE(flags.find(" hg"), std::string::npos) << flags;
  // The small buffer lives in the heap, which is not advised (a sanitizer's
  // allocator maps its own heap, with flags of its choosing).
  if (!tpr::testing::kAddressSanitizer && !tpr::testing::kThreadSanitizer) {
    EXPECT_EQ(VmFlagsOf(small.data()).find(" hg"), std::string::npos);
  }
}

TEST(VpTreeOrderTest, EveryItemOnceNeighboursAdjacent) {
  const std::vector<PreparedSignature> items = Draw(600, 8);
  VpTreeOptions options;
  options.leaf_size = 16;
  absl::StatusOr<VpTree> tree = VpTree::Build(
      items.size(),
      [&](uint32_t i, uint32_t j) {
        return Distance(items[i], items[j], IntentWeights(Intent::kBalanced));
      },
      options);
  ASSERT_TRUE(tree.ok()) << tree.status();
  const std::vector<uint32_t> order = tree->ItemsInTreeOrder();
  std::vector<uint32_t> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  std::vector<uint32_t> all(items.size());
  std::iota(all.begin(), all.end(), 0u);
  EXPECT_EQ(sorted, all);
  // Depth first, consecutive items mostly share a bucket or a subtree, so
  // they are much closer on average than pairs taken without the tree.
  double consecutive = 0.0;
  double shuffled = 0.0;
  for (size_t k = 0; k + 1 < order.size(); ++k) {
    const TermWeights w = IntentWeights(Intent::kBalanced);
    consecutive += Distance(items[order[k]], items[order[k + 1]], w);
    shuffled += Distance(items[k], items[(k * 7 + 13) % items.size()], w);
  }
  EXPECT_LT(consecutive, 0.8 * shuffled);
  // Deterministic: the same tree gives the same order.
  EXPECT_EQ(tree->ItemsInTreeOrder(), order);
}

}  // namespace
}  // namespace tpr::index
