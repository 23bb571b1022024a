// The VP-tree's stored layout (VpTree::Node, VpTree::Data), shared by its
// search (vp_tree.cc), build (vp_tree_build.cc) and serialization
// (vp_tree_serialize.cc). Internal to indexer/lib: include vp_tree.h.
#ifndef TPR_INDEXER_LIB_INTERNAL_VP_TREE_DATA_H_
#define TPR_INDEXER_LIB_INTERNAL_VP_TREE_DATA_H_

#include <cstddef>
#include <cstdint>
#include <vector>

#include "indexer/lib/huge_pages.h"
#include "indexer/lib/vp_tree.h"

namespace tpr::index {
namespace vp_tree_internal {

// kNone marks an absent node or item id.
inline constexpr uint32_t kNone = 0xffffffffu;

}  // namespace vp_tree_internal

struct VpTree::Node {
  uint32_t parent = vp_tree_internal::kNone;
  uint32_t vp = vp_tree_internal::kNone;  // vp_tree_internal::kNone: a leaf
  uint32_t inner = vp_tree_internal::kNone;
  uint32_t outer = vp_tree_internal::kNone;
  uint32_t begin = 0;  // leaf bucket: leaf_items[begin, end)
  uint32_t end = 0;
  uint32_t depth = 0;  // number of ancestors (derived)
  // ranges[range_offset + 2 (j terms + t)], j < depth, t < terms (derived)
  uint64_t range_offset = 0;
};

struct VpTree::Data {
  uint32_t n_items = 0;
  size_t height = 0;
  size_t terms = 1;
  TermVector build_weights = {1.0, 0.0, 0.0};
  // The arrays a search reads are huge-page advised (huge_pages.h): at 1M
  // items item_dists alone is about 110 MB, read at a random bucket per
  // visited leaf.
  HugeVector<Node> nodes;
  HugeVector<uint32_t> leaf_items;
  // Per node, per ancestor (root first), per term: min and max term
  // distance from that ancestor's vantage point to the items of the node's
  // subtree.
  HugeVector<double> ranges;
  // Per item: the node holding it, and its term distances to the vantage
  // points of that node's ancestors (root first), in float32. The values
  // of one node (a vantage point's, or its bucket's c items in leaf_items
  // order) form one block in node order; in it, term t, ancestor j of the
  // item at bucket position k is at block + (t depth + j) c + k, and
  // item_row[item] = block + k (ItemValue). Serialized bytes keep them in
  // item-id order, independent of this layout.
  std::vector<uint32_t> item_holder;
  HugeVector<uint64_t> item_row;
  HugeVector<float> item_dists;

  // Sets item_row from nodes (with depths), leaf_items and the vantage
  // points, in the tree-order layout above; returns the total length.
  uint64_t AssignRows();
  // BlockItems returns c of the block holding `item`: 1 for a vantage
  // point, the bucket's size for a leaf item.
  uint64_t BlockItems(uint32_t item) const {
    const Node& n = nodes[item_holder[item]];
    return n.vp != vp_tree_internal::kNone ? 1 : n.end - n.begin;
  }
  // ItemValue returns the index in item_dists of term t's distance from
  // `item` to its j-th ancestor's vantage point.
  uint64_t ItemValue(uint32_t item, uint32_t j, size_t t) const {
    const uint64_t depth = nodes[item_holder[item]].depth;
    return item_row[item] + (t * depth + j) * BlockItems(item);
  }
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_INTERNAL_VP_TREE_DATA_H_
