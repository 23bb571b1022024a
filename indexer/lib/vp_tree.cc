// VP-tree best-first ranked search (Tam & Lau 2007 section 6.2); the build
// is vp_tree_build.cc, the serialization vp_tree_serialize.cc, the layout
// they share internal/vp_tree_data.h. Design notes:
// - Every term distance computed while partitioning (item x to the vantage
//   point of each ancestor) is kept, per term. A node stores [min, max] of
//   each term's distances over its subtree for every ancestor, and a leaf
//   item its own values, so a search bounds a subtree or an item by the
//   triangle inequality of each term against ALL ancestors' vantage points,
//   not only the parent's, at no metric cost, under any weighting. Memory
//   is O(n log n) floats per term (about 14 per item and term at n = 100k).
// - The item values are float32 (a bound subtracts the rounding, below)
//   and laid out in tree order: one block per bucket (or vantage point),
//   term-major, then ancestor-major, then item (item_row below), so that
//   scanning a bucket reads one linear block per term (with rows in
//   item-id order a scan took a cache miss per item and dominated a 10-NN
//   query over 100k items), a term whose weight is 0 is never read, and
//   the inner loop runs over the bucket's items with unit stride.
// - The search is the incremental nearest-neighbour algorithm of Hjaltason
//   and Samet: one priority queue holds nodes (keyed by lower bound) and
//   items (keyed by a lower bound that is refined lazily: stored distances,
//   then the caller's cheap bound, then the metric; a bucket's items enter
//   as one "run" entry over a heap of their own, so the main queue stays
//   small with large buckets). An item is returned
//   when its exact distance is the smallest key left, hence certain; the
//   metric is evaluated only for items whose bounds fall below the answer.
// - Computed bounds are deflated by a relative 1e-9 before use: the metric
//   (an EMD from a simplex) satisfies the triangle inequality only to
//   rounding, and an overestimated bound could reorder ties or lose an item.
//   Bounds from the float32 item values are deflated by a relative 1e-7:
//   a stored value r~ = fl32(r) is within 2^-24 r (6e-8) of r, so
//   |q - r~| - 1e-7 max(q, r~) <= |q - r| - 1e-9 max(q, r).
#include "indexer/lib/vp_tree.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <queue>
#include <random>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "indexer/lib/byte_codec.h"
#include "indexer/lib/huge_pages.h"
#include "indexer/lib/internal/vp_tree_data.h"

namespace tpr::index {

using vp_tree_internal::kNone;

namespace {

constexpr double kRelativeSlack = 1e-9;
constexpr double kStoredSlack = 1e-7;  // bounds from float32 item values

// A triangle-inequality bound, made safe against the metric's rounding.
double Deflate(double bound, double scale) {
  const double b = bound - kRelativeSlack * scale;
  return b > 0.0 ? b : 0.0;
}

}  // namespace

VpTree::VpTree() : data_(std::make_unique<Data>()) {}

size_t VpTree::MemoryBytes() const {
  const Data& d = *data_;
  return sizeof(Data) + d.nodes.capacity() * sizeof(Node) +
         d.leaf_items.capacity() * sizeof(uint32_t) +
         d.ranges.capacity() * sizeof(double) +
         d.item_holder.capacity() * sizeof(uint32_t) +
         d.item_row.capacity() * sizeof(uint64_t) +
         d.item_dists.capacity() * sizeof(float);
}
VpTree::~VpTree() = default;
VpTree::VpTree(VpTree&&) noexcept = default;
VpTree& VpTree::operator=(VpTree&&) noexcept = default;

uint64_t VpTree::Data::AssignRows() {
  item_row.assign(n_items, 0);
  uint64_t row = 0;
  for (const Node& n : nodes) {
    if (n.vp != kNone) {
      item_row[n.vp] = row;
      row += n.depth * terms;
      continue;
    }
    for (uint32_t p = n.begin; p < n.end; ++p) {
      item_row[leaf_items[p]] = row + (p - n.begin);
    }
    row += static_cast<uint64_t>(n.depth) * terms * (n.end - n.begin);
  }
  return row;
}

std::vector<uint32_t> VpTree::ItemsInTreeOrder() const {
  const Data& d = *data_;
  std::vector<uint32_t> order;
  order.reserve(d.n_items);
  for (const Node& n : d.nodes) {
    if (n.vp != kNone) {
      order.push_back(n.vp);
      continue;
    }
    order.insert(order.end(), d.leaf_items.begin() + n.begin,
                 d.leaf_items.begin() + n.end);
  }
  return order;
}

size_t VpTree::size() const { return data_->n_items; }
size_t VpTree::terms() const { return data_->terms; }
const TermVector& VpTree::build_weights() const { return data_->build_weights; }

absl::Status ValidateWeights(const TermVector& w, size_t terms) {
  bool any = false;
  for (size_t t = 0; t < terms && t < kMaxTerms; ++t) {
    if (!std::isfinite(w[t]) || w[t] < 0.0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "weight of term ", t, " is ", w[t], "; it must be finite and >= 0"));
    }
    any = any || w[t] > 0.0;
  }
  if (!any) return absl::InvalidArgumentError("every term weight is 0");
  return absl::OkStatus();
}
size_t VpTree::height() const { return data_->height; }
size_t VpTree::node_count() const { return data_->nodes.size(); }

// ---------------------------------------------------------------------------
// Search

class VpCursor : public NeighborCursor {
 public:
  VpCursor(const VpTree::Data* data, QuerySpec spec)
      : data_(data), spec_(std::move(spec)), queue_(Later{this}) {
    assert(ValidateWeights(spec_.weights, data_->terms).ok());
    for (size_t t = 0; t < data_->terms; ++t) {
      if (spec_.weights[t] > 0.0) active_[active_count_++] = t;
    }
    if (!data_->nodes.empty()) {
      dq_.assign(data_->nodes.size() * data_->terms,
                 std::numeric_limits<double>::quiet_NaN());
      queue_.push({0.0, 0, kNode, 0});
    }
    run_.clear();
    for (uint32_t item : spec_.extra_items) AddToRun(item, 0.0);
    PushRun();
  }

  std::optional<ItemNeighbor> Next() override {
    while (!queue_.empty()) {
      // Polled before anything that may compute a distance (an exact item
      // is returned as found); sticky once true.
      if (queue_.top().kind != kItemExact && spec_.stop &&
          (stopped_ || (stopped_ = spec_.stop()))) {
        return std::nullopt;
      }
      Entry e = PopItemOrNode();
      switch (e.kind) {
        case kNode:
          Expand(e);
          break;
        case kRun:
          break;  // PopItemOrNode never returns a run
        case kItemBound: {
          if (spec_.parallel_for && spec_.parallel_batch > 1) {
            RefineBatch(e);
            break;
          }
          if (spec_.prefetch) PrefetchNext();
          // e.level bounds of the cascade have been applied; apply the next
          // ones, then the metric. While the refined key stays strictly
          // below every other key the item would be popped next anyway, so
          // it is refined on the spot (same order, no queue round trip, and
          // a bound's cached work, such as the EMD's ground matrix, is
          // still warm for the next level).
          bool alive = true;
          bool next = true;  // still strictly the smallest key
          while (e.level < spec_.lower_bounds.size()) {
            ++stats_.lower_bounds;
            const double lb = spec_.lower_bounds[e.level](e.index);
            e.key = std::max(e.key, Deflate(lb, lb));
            ++e.level;
            if (!(e.key <= spec_.radius)) {
              alive = false;
              break;
            }
            next = queue_.empty() || e.key < queue_.top().key;
            if (!next) break;
          }
          if (!alive) break;
          if (!next) {
            queue_.push(e);
            break;
          }
          ++stats_.emd_computations;
          double terms[kMaxTerms];
          const double d = Evaluate(e.index, terms);
          if (d <= spec_.radius) queue_.push({d, e.index, kItemExact, 0});
          break;
        }
        case kItemExact:
          return ItemNeighbor{e.index, e.key};
      }
    }
    return std::nullopt;
  }

  const SearchStats& stats() const override { return stats_; }

  // Evaluate returns d_w(query, item), leaving the term distances in
  // terms[0..kMaxTerms) (NaN for a term whose weight is 0). Thread-safe
  // when spec_.distance is.
  double Evaluate(uint32_t item, double* terms) const {
    for (size_t t = 0; t < kMaxTerms; ++t) {
      terms[t] = std::numeric_limits<double>::quiet_NaN();
    }
    spec_.distance(item, terms);
    double d = 0.0;
    for (size_t a = 0; a < active_count_; ++a) {
      d += spec_.weights[active_[a]] * terms[active_[a]];
    }
    return d;
  }

 private:
  // Calls spec_.prefetch for the item under the smallest key left (an
  // unrefined item, or a run's smallest item), if there is one: the item
  // the search most likely refines after the current one.
  void PrefetchNext() {
    if (queue_.empty()) return;
    const Entry& top = queue_.top();
    if (top.kind == kItemBound) {
      spec_.prefetch(top.index, top.level);
    } else if (top.kind == kRun) {
      spec_.prefetch(runs_[top.index].front().second, 0);
    }
  }

  // Pops the smallest entry; a run gives up its smallest item (the run's
  // smallest bound is the smallest key left) as an item entry.
  struct Entry;
  Entry PopItemOrNode();
  // The parallel form of one kItemBound step: takes `e` and the next
  // entries while they are items (up to spec_.parallel_batch), then, through
  // spec_.parallel_for, refines each through its remaining bounds and
  // computes its distance when its key stays strictly below every entry
  // left in the queue (cutoff). Those items are exactly the ones the serial
  // loop would evaluate next, in some order, unless the caller stops first;
  // so answers and their order are unchanged and the extra work is at most
  // one batch at the end of a search.
  void RefineBatch(const Entry& e);

  // kRun: a bucket's items still keyed by their stored-distance bounds,
  // kept in a heap of their own (runs_) so that the main queue holds one
  // entry per bucket instead of one per item (buckets are large).
  enum Kind : uint8_t { kNode, kRun, kItemBound, kItemExact };
  struct Entry {
    double key;
    uint32_t index;  // node or item
    Kind kind;
    // kItemBound: how many of spec_.lower_bounds have been applied (0: only
    // the stored distances). Refining is cheapest first, so at equal keys
    // the entry with fewer levels applied is refined first.
    uint8_t level = 0;
  };
  // Heap order: smaller key first; at equal keys every bound (node or
  // unrefined item) before any exact item, so that an exact item is
  // returned only when nothing left can tie with it and precede it; among
  // exact ties, tie_less.
  struct Later {
    const VpCursor* self;
    bool operator()(const Entry& a, const Entry& b) const {
      if (a.key != b.key) return a.key > b.key;
      const bool a_exact = a.kind == kItemExact;
      const bool b_exact = b.kind == kItemExact;
      if (a_exact != b_exact) return a_exact;
      if (a_exact) {
        return self->spec_.tie_less ? self->spec_.tie_less(b.index, a.index)
                                    : b.index < a.index;
      }
      if (a.kind != b.kind) return a.kind > b.kind;
      if (a.level != b.level) return a.level > b.level;
      return a.index > b.index;
    }
  };

  struct Slot {
    Entry entry;
    double distance = 0.0;
    int64_t bounds = 0;
    bool dead = false;   // beyond the radius
    bool exact = false;  // distance computed
  };
  std::vector<Entry> batch_;  // scratch of RefineBatch
  std::vector<Slot> slots_;   // scratch of RefineBatch

  // Adds an item to run_ (scratch) unless rejected or beyond the radius.
  void AddToRun(uint32_t item, double bound) {
    if (spec_.accept && !spec_.accept(item)) return;
    if (!(bound <= spec_.radius)) return;
    run_.emplace_back(bound, item);
  }
  // Queues run_ as one entry (a min-heap on (bound, item)) and clears it.
  void PushRun() {
    if (run_.empty()) return;
    std::make_heap(run_.begin(), run_.end(), std::greater<>());
    const uint32_t id = static_cast<uint32_t>(runs_.size());
    queue_.push({run_.front().first, id, kRun, 0});
    runs_.push_back(std::move(run_));
    run_.clear();
  }

  // Collects the query's term distances to the vantage points of `node`'s
  // ancestors, root first, into path_: term t, ancestor j at
  // path_[t depth + j] (NaN where unknown or the term's weight is 0).
  void CollectPath(const VpTree::Node& node) {
    const size_t terms = data_->terms;
    path_.resize(node.depth * terms);
    uint32_t p = node.parent;
    for (uint32_t j = node.depth; j-- > 0;) {
      for (size_t t = 0; t < terms; ++t) {
        path_[t * node.depth + j] = dq_[p * terms + t];
      }
      p = data_->nodes[p].parent;
    }
  }

  // Lower bound on d_w(query, x) for x below `child` from its stored
  // ranges: max(floor, sum_t w_t L_t), L_t the best bound of term t.
  double NodeBound(uint32_t child, double floor) {
    const VpTree::Node& node = data_->nodes[child];
    CollectPath(node);
    const size_t terms = data_->terms;
    const double* r = &data_->ranges[node.range_offset];
    double sum = 0.0;
    for (size_t a = 0; a < active_count_; ++a) {
      const size_t t = active_[a];
      double term = 0.0;
      for (uint32_t j = 0; j < node.depth; ++j) {
        const double q = path_[t * node.depth + j];
        if (std::isnan(q)) continue;
        const double lo = r[2 * (j * terms + t)];
        const double hi = r[2 * (j * terms + t) + 1];
        if (q < lo) {
          term = std::max(term, Deflate(lo - q, lo));
        } else if (q > hi) {
          term = std::max(term, Deflate(q - hi, q));
        }
      }
      sum += spec_.weights[t] * term;
    }
    return std::max(floor, sum);
  }

  // Sets bucket_bounds_[k] to sum_t w_t L_t for the c items of the leaf
  // whose block starts at `block`, L_t the best bound of term t from the
  // stored float32 values (deflated by kStoredSlack, see the file comment).
  // path_ must hold the leaf's path. Written without branches, the inner
  // loop over the bucket with unit stride, so that the compiler vectorizes
  // it.
  void BucketBounds(const float* block, uint32_t depth, uint32_t c) {
    bucket_bounds_.assign(c, 0.0);
    term_bounds_.resize(c);
    double* sum = bucket_bounds_.data();
    double* m = term_bounds_.data();
    for (size_t a = 0; a < active_count_; ++a) {
      const size_t t = active_[a];
      std::fill(m, m + c, 0.0);
      for (uint32_t j = 0; j < depth; ++j) {
        const double q = path_[t * depth + j];
        const float* r = block + (t * depth + j) * c;
        // std::max(m, NaN) keeps m: an unknown q (a vantage point whose
        // distance is NaN) bounds nothing.
        for (uint32_t k = 0; k < c; ++k) {
          const double v = static_cast<double>(r[k]);
          const double b = std::fabs(q - v) - kStoredSlack * std::max(q, v);
          m[k] = std::max(m[k], b);
        }
      }
      const double w = spec_.weights[t];
      for (uint32_t k = 0; k < c; ++k) sum[k] += w * m[k];
    }
  }

  void Expand(const Entry& e) {
    ++stats_.nodes_visited;
    const VpTree::Node& node = data_->nodes[e.index];
    if (node.vp == kNone) {
      CollectPath(node);
      run_.clear();
      if (node.begin == node.end) return;
      // The bucket's values are one block (see Data).
      // data() + offset, not &v[offset]: a tree that is one leaf has no
      // stored distances, and indexing an empty vector is undefined
      // (UBSan, found by tests/fuzz fuzz_vp_tree_load).
      const uint32_t c = node.end - node.begin;
      BucketBounds(data_->item_dists.data() +
                       data_->item_row[data_->leaf_items[node.begin]],
                   node.depth, c);
      for (uint32_t k = 0; k < c; ++k) {
        AddToRun(data_->leaf_items[node.begin + k],
                 std::max(e.key, bucket_bounds_[k]));
      }
      PushRun();
      return;
    }
    ++stats_.emd_computations;
    double terms[kMaxTerms];
    const double d = Evaluate(node.vp, terms);
    for (size_t t = 0; t < data_->terms; ++t) {
      dq_[e.index * data_->terms + t] = terms[t];
    }
    if ((!spec_.accept || spec_.accept(node.vp)) && d <= spec_.radius) {
      queue_.push({d, node.vp, kItemExact, 0});
    }
    for (uint32_t child : {node.inner, node.outer}) {
      if (child == kNone) continue;
      const double bound = NodeBound(child, e.key);
      if (!(bound <= spec_.radius)) continue;
      queue_.push({bound, child, kNode, 0});
      // Off by default: then the child's node is not read here at all.
      if (spec_.prefetch_vantage_points && spec_.prefetch) {
        const uint32_t vp = data_->nodes[child].vp;
        if (vp != kNone) spec_.prefetch(vp, spec_.lower_bounds.size());
      }
    }
  }

  const VpTree::Data* data_;
  QuerySpec spec_;
  // The terms whose weight is > 0, in term order.
  size_t active_[kMaxTerms] = {};
  size_t active_count_ = 0;
  bool stopped_ = false;  // spec_.stop returned true
  SearchStats stats_;
  // Per node and term: d_t(query, vantage point) at node terms + t.
  std::vector<double> dq_;
  std::vector<double> path_;                      // scratch
  std::vector<double> bucket_bounds_;             // scratch of BucketBounds
  std::vector<double> term_bounds_;               // scratch of BucketBounds
  std::vector<std::pair<double, uint32_t>> run_;  // scratch
  std::vector<std::vector<std::pair<double, uint32_t>>> runs_;
  std::priority_queue<Entry, std::vector<Entry>, Later> queue_;
};

VpCursor::Entry VpCursor::PopItemOrNode() {
  Entry e = queue_.top();
  queue_.pop();
  if (e.kind != kRun) return e;
  std::vector<std::pair<double, uint32_t>>& run = runs_[e.index];
  std::pop_heap(run.begin(), run.end(), std::greater<>());
  const std::pair<double, uint32_t> next = run.back();
  run.pop_back();
  if (!run.empty()) queue_.push({run.front().first, e.index, kRun, 0});
  return Entry{next.first, next.second, kItemBound, 0};
}

void VpCursor::RefineBatch(const Entry& e) {
  batch_.clear();
  batch_.push_back(e);
  while (batch_.size() < spec_.parallel_batch && !queue_.empty() &&
         (queue_.top().kind == kItemBound || queue_.top().kind == kRun)) {
    batch_.push_back(PopItemOrNode());
  }
  const double cutoff = queue_.empty() ? std::numeric_limits<double>::infinity()
                                       : queue_.top().key;
  const size_t levels = spec_.lower_bounds.size();
  slots_.assign(batch_.size(), Slot{});
  spec_.parallel_for(batch_.size(), [&](size_t i) {
    Slot& slot = slots_[i];
    Entry x = batch_[i];
    while (x.level < levels) {
      ++slot.bounds;
      const double lb = spec_.lower_bounds[x.level](x.index);
      x.key = std::max(x.key, Deflate(lb, lb));
      ++x.level;
      if (!(x.key <= spec_.radius)) {
        slot.dead = true;
        break;
      }
      if (!(x.key < cutoff)) break;
    }
    slot.entry = x;
    if (!slot.dead && x.level == levels && x.key < cutoff) {
      double terms[kMaxTerms];
      slot.distance = Evaluate(x.index, terms);
      slot.exact = true;
    }
  });
  for (const Slot& slot : slots_) {
    stats_.lower_bounds += slot.bounds;
    if (slot.dead) continue;
    if (!slot.exact) {
      queue_.push(slot.entry);
      continue;
    }
    ++stats_.emd_computations;
    if (slot.distance <= spec_.radius) {
      queue_.push({slot.distance, slot.entry.index, kItemExact, 0});
    }
  }
}

std::unique_ptr<NeighborCursor> VpTree::Search(QuerySpec spec) const {
  return std::make_unique<VpCursor>(data_.get(), std::move(spec));
}

std::vector<ItemNeighbor> VpTree::Knn(QuerySpec spec, size_t k,
                                      SearchStats* stats) const {
  std::vector<ItemNeighbor> out;
  if (k == 0) {
    if (stats != nullptr) *stats = SearchStats{};
    return out;
  }
  return TakeNeighbors(*Search(std::move(spec)), k, stats);
}

std::vector<ItemNeighbor> TakeNeighbors(NeighborCursor& cursor, size_t k,
                                        SearchStats* stats) {
  std::vector<ItemNeighbor> out;
  while (out.size() < k) {
    std::optional<ItemNeighbor> next = cursor.Next();
    if (!next) break;
    out.push_back(*next);
  }
  if (stats != nullptr) *stats = cursor.stats();
  return out;
}

std::vector<ItemNeighbor> VpTree::Range(QuerySpec spec,
                                        SearchStats* stats) const {
  return Knn(std::move(spec), static_cast<size_t>(-1), stats);
}

}  // namespace tpr::index
