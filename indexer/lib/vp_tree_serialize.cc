// VP-tree serialization (VpTree::Serialize, VpTree::Deserialize), over the
// layout of internal/vp_tree_data.h.
#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <cstring>
#include <random>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "indexer/lib/byte_codec.h"
#include "indexer/lib/internal/vp_tree_data.h"
#include "indexer/lib/vp_tree.h"

namespace tpr::index {

using vp_tree_internal::kNone;

// ---------------------------------------------------------------------------
// Serialization: little-endian fixed-width fields, FNV-1a 64 checksum last.
//   "TPRVPT" u16 version | u32 n_items | u32 n_nodes
//   u32 terms | terms x f64 build weight
//   per node: u32 parent, vp, inner, outer, begin, end
//   u32 n_leaf_items, u32 each | u64 n_ranges, f64 each (node order, then
//   ancestor, then term: min, max)
//   u64 n_item_dists, f32 bits each (item order, then ancestor, then term)
//   | u64 checksum of everything before

namespace {

constexpr Frame kFrame{"TPRVPT", /*version=*/2, "VP-tree",
                       "corrupt VP-tree bytes"};

void PutF32(std::string* out, float v) {
  uint32_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  PutU(out, bits, 4);
}

bool ReadF32(ByteReader* r, float* v) {
  uint32_t bits;
  if (!r->U32(&bits)) return false;
  std::memcpy(v, &bits, sizeof bits);
  return true;
}

absl::Status Corrupt(absl::string_view what) {
  return CorruptFrame(kFrame, what);
}

}  // namespace

std::string VpTree::Serialize() const {
  const Data& d = *data_;
  std::string out = BeginFrame(kFrame);
  PutU(&out, d.n_items, 4);
  PutU(&out, d.nodes.size(), 4);
  PutU(&out, d.terms, 4);
  for (size_t t = 0; t < d.terms; ++t) PutF(&out, d.build_weights[t]);
  for (const Node& n : d.nodes) {
    for (uint32_t v : {n.parent, n.vp, n.inner, n.outer, n.begin, n.end}) {
      PutU(&out, v, 4);
    }
  }
  PutU(&out, d.leaf_items.size(), 4);
  for (uint32_t v : d.leaf_items) PutU(&out, v, 4);
  PutU(&out, d.ranges.size(), 8);
  for (double v : d.ranges) PutF(&out, v);
  // Values in item-id order, whatever the memory layout.
  PutU(&out, d.item_dists.size(), 8);
  for (uint32_t item = 0; item < d.n_items; ++item) {
    const uint32_t depth = d.nodes[d.item_holder[item]].depth;
    for (uint32_t j = 0; j < depth; ++j) {
      for (size_t t = 0; t < d.terms; ++t) {
        PutF32(&out, d.item_dists[d.ItemValue(item, j, t)]);
      }
    }
  }
  EndFrame(&out);
  return out;
}

class VpTreeReader {
 public:
  // Records `node` as the holder of `item`; false for an unknown item or
  // one held twice.
  static bool Claim(VpTree::Data* d, uint32_t item, uint32_t node) {
    if (item >= d->n_items || d->item_holder[item] != kNone) return false;
    d->item_holder[item] = node;
    return true;
  }

  static absl::StatusOr<VpTree> Read(absl::string_view bytes) {
    absl::StatusOr<absl::string_view> payload = OpenFrame(bytes, kFrame);
    if (!payload.ok()) return payload.status();
    ByteReader r(*payload);

    VpTree tree;
    VpTree::Data& d = *tree.data_;
    uint32_t n_nodes;
    if (!r.U32(&d.n_items) || !r.U32(&n_nodes))
      return Corrupt("truncated header");
    if (d.n_items == kNone) return Corrupt("item count");
    uint32_t terms;
    if (!r.U32(&terms) || terms < 1 || terms > kMaxTerms) {
      return Corrupt("term count");
    }
    d.terms = terms;
    d.build_weights = TermVector{};
    for (size_t t = 0; t < d.terms; ++t) {
      if (!r.F(&d.build_weights[t])) return Corrupt("truncated build weights");
    }
    if (!ValidateWeights(d.build_weights, d.terms).ok()) {
      return Corrupt("build weights");
    }
    if (static_cast<uint64_t>(n_nodes) * 24 > r.remaining()) {
      return Corrupt("node count exceeds the bytes");
    }
    if ((n_nodes == 0) != (d.n_items == 0))
      return Corrupt("empty tree mismatch");
    d.nodes.resize(n_nodes);
    for (VpTree::Node& n : d.nodes) {
      r.U32(&n.parent);
      r.U32(&n.vp);
      r.U32(&n.inner);
      r.U32(&n.outer);
      r.U32(&n.begin);
      r.U32(&n.end);
    }
    uint32_t n_leaf;
    if (!r.U32(&n_leaf) || static_cast<uint64_t>(n_leaf) * 4 > r.remaining()) {
      return Corrupt("leaf item count");
    }
    d.leaf_items.resize(n_leaf);
    for (uint32_t& v : d.leaf_items) r.U32(&v);

    // Every item is a vantage point or in a bucket: check the count before
    // allocating per-item arrays from it.
    uint64_t internal = 0;
    for (const VpTree::Node& n : d.nodes) internal += n.vp != kNone ? 1 : 0;
    if (internal + n_leaf != d.n_items) return Corrupt("item count");

    // Structure: node i's parent precedes it and names it as a child, so
    // the nodes form one tree rooted at 0; depths and offsets follow.
    d.item_holder.assign(d.n_items, kNone);
    uint64_t range_total = 0;
    uint64_t next_leaf = 0;
    for (uint32_t i = 0; i < n_nodes; ++i) {
      VpTree::Node& n = d.nodes[i];
      if (i == 0) {
        if (n.parent != kNone) return Corrupt("root has a parent");
        n.depth = 0;
      } else {
        if (n.parent >= i) return Corrupt(absl::StrCat("node ", i, " parent"));
        const VpTree::Node& p = d.nodes[n.parent];
        if (p.inner != i && p.outer != i) {
          return Corrupt(
              absl::StrCat("node ", i, " not a child of its parent"));
        }
        n.depth = p.depth + 1;
      }
      n.range_offset = range_total;
      range_total += 2ull * n.depth * d.terms;
      d.height = std::max<size_t>(d.height, n.depth);
      if (n.vp == kNone) {
        if (n.inner != kNone || n.outer != kNone || n.begin != next_leaf ||
            n.end < n.begin || n.end > n_leaf) {
          return Corrupt(absl::StrCat("leaf ", i));
        }
        next_leaf = n.end;
        for (uint32_t p = n.begin; p < n.end; ++p) {
          if (!Claim(&d, d.leaf_items[p], i)) return Corrupt("leaf item");
        }
      } else {
        if (n.begin != 0 || n.end != 0 || n.inner == n.outer) {
          return Corrupt(absl::StrCat("node ", i));
        }
        for (uint32_t c : {n.inner, n.outer}) {
          if (c == kNone) continue;
          if (c <= i || c >= n_nodes || d.nodes[c].parent != i) {
            return Corrupt(absl::StrCat("node ", i, " child"));
          }
        }
        if (!Claim(&d, n.vp, i)) return Corrupt("vantage point");
      }
    }
    if (next_leaf != n_leaf) return Corrupt("unreferenced leaf items");
    uint64_t dist_total = 0;
    for (uint32_t item = 0; item < d.n_items; ++item) {
      if (d.item_holder[item] == kNone) {
        return Corrupt(absl::StrCat("item ", item, " missing"));
      }
      dist_total +=
          static_cast<uint64_t>(d.nodes[d.item_holder[item]].depth) * d.terms;
    }

    uint64_t n_ranges;
    if (!r.U(8, &n_ranges) || n_ranges != range_total ||
        n_ranges * 8 > r.remaining()) {
      return Corrupt("range count");
    }
    d.ranges.resize(n_ranges);
    for (size_t j = 0; j < n_ranges; ++j) {
      r.F(&d.ranges[j]);
      if (!(d.ranges[j] >= 0.0) || !std::isfinite(d.ranges[j])) {
        return Corrupt("range value");
      }
      if (j % 2 == 1 && d.ranges[j - 1] > d.ranges[j]) {
        return Corrupt("range min > max");
      }
    }
    uint64_t n_dists;
    if (!r.U(8, &n_dists) || n_dists != dist_total ||
        n_dists * 4 != r.remaining()) {
      return Corrupt("item distance count");
    }
    // The bytes hold values in item-id order; memory in tree-order blocks.
    d.AssignRows();
    d.item_dists.resize(n_dists);
    for (uint32_t item = 0; item < d.n_items; ++item) {
      const uint32_t depth = d.nodes[d.item_holder[item]].depth;
      for (uint32_t j = 0; j < depth; ++j) {
        for (size_t t = 0; t < d.terms; ++t) {
          float& v = d.item_dists[d.ItemValue(item, j, t)];
          ReadF32(&r, &v);
          if (!(v >= 0.0f) || !std::isfinite(v)) {
            return Corrupt("item distance");
          }
        }
      }
    }
    return tree;
  }
};

absl::StatusOr<VpTree> VpTree::Deserialize(absl::string_view bytes) {
  return VpTreeReader::Read(bytes);
}

}  // namespace tpr::index
