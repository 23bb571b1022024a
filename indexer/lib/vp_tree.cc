// VP-tree build, best-first ranked search and serialization (Tam & Lau 2007
// section 6.2). Design notes:
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

namespace tpr::index {

namespace {

constexpr uint32_t kNone = 0xffffffffu;
constexpr double kRelativeSlack = 1e-9;
constexpr double kStoredSlack = 1e-7;  // bounds from float32 item values

// A triangle-inequality bound, made safe against the metric's rounding.
double Deflate(double bound, double scale) {
  const double b = bound - kRelativeSlack * scale;
  return b > 0.0 ? b : 0.0;
}

}  // namespace

struct VpTree::Node {
  uint32_t parent = kNone;
  uint32_t vp = kNone;  // kNone: a leaf
  uint32_t inner = kNone;
  uint32_t outer = kNone;
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
    return n.vp != kNone ? 1 : n.end - n.begin;
  }
  // ItemValue returns the index in item_dists of term t's distance from
  // `item` to its j-th ancestor's vantage point.
  uint64_t ItemValue(uint32_t item, uint32_t j, size_t t) const {
    const uint64_t depth = nodes[item_holder[item]].depth;
    return item_row[item] + (t * depth + j) * BlockItems(item);
  }
};

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
// Build

class VpTreeBuilder {
 public:
  VpTreeBuilder(size_t n, size_t terms, const PairTerms& distance,
                const TermVector& build_weights, const VpTreeOptions& options,
                const std::atomic<bool>* cancel)
      : n_(n),
        terms_(terms),
        distance_(distance),
        build_weights_(build_weights),
        options_(options),
        cancel_(cancel) {}

  absl::StatusOr<VpTree> Run() {
    if (options_.leaf_size < 1) {
      return absl::InvalidArgumentError("VpTreeOptions.leaf_size must be >= 1");
    }
    if (options_.vantage_candidates < 1 || options_.vantage_sample < 1) {
      return absl::InvalidArgumentError(
          "VpTreeOptions.vantage_candidates and vantage_sample must be >= 1");
    }
    if (options_.build_threads < 1) {
      return absl::InvalidArgumentError(
          "VpTreeOptions.build_threads must be >= 1");
    }
    if (n_ >= kNone) {
      return absl::InvalidArgumentError(
          absl::StrCat("VP-tree of ", n_, " items: at most 2^32 - 2"));
    }
    if (n_ > 0 && !distance_) {
      return absl::InvalidArgumentError("VP-tree build without a distance");
    }
    if (terms_ < 1 || terms_ > kMaxTerms) {
      return absl::InvalidArgumentError(absl::StrCat(
          "VP-tree of ", terms_, " terms: 1 to ", kMaxTerms, " allowed"));
    }
    if (absl::Status s = ValidateWeights(build_weights_, terms_); !s.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("VP-tree build weights: ", s.message()));
    }
    VpTree tree;
    data_ = tree.data_.get();
    data_->n_items = static_cast<uint32_t>(n_);
    data_->terms = terms_;
    data_->build_weights = TermVector{};
    for (size_t t = 0; t < terms_; ++t) {
      data_->build_weights[t] = build_weights_[t];
    }
    data_->item_holder.assign(n_, kNone);
    rows_.assign(n_, {});
    work_.resize(n_);
    for (size_t i = 0; i < n_; ++i) work_[i] = static_cast<uint32_t>(i);
    if (n_ > 0) BuildNode(kNone, 0, 0, static_cast<uint32_t>(n_));
    if (cancelled_) return absl::CancelledError("VP-tree build cancelled");
    // Flatten the per-item rows into the tree-order blocks.
    data_->item_dists.resize(data_->AssignRows());
    for (uint32_t i = 0; i < n_; ++i) {
      const uint32_t depth = data_->nodes[data_->item_holder[i]].depth;
      for (uint32_t j = 0; j < depth; ++j) {
        for (size_t t = 0; t < terms_; ++t) {
          data_->item_dists[data_->ItemValue(i, j, t)] =
              static_cast<float>(rows_[i][j * terms_ + t]);
        }
      }
      std::vector<double>().swap(rows_[i]);
    }
    return tree;
  }

 private:
  bool Cancelled() {
    if (!cancelled_ && cancel_ != nullptr && cancel_->load()) cancelled_ = true;
    return cancelled_;
  }

  // The build weighting's distance of one item's term values.
  double Weighted(const double* terms) const {
    double d = 0.0;
    for (size_t t = 0; t < terms_; ++t) {
      if (build_weights_[t] > 0.0) d += build_weights_[t] * terms[t];
    }
    return d;
  }

  // Computes out[i terms + t] = d_t(vp, items[i]) for all i and t, split
  // across threads for large nodes (each thread writes only its own slots).
  void DistancesTo(uint32_t vp, const uint32_t* items, size_t count,
                   double* out) {
    const size_t threads = static_cast<size_t>(options_.build_threads);
    auto some = [this, vp, items, out](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) distance_(vp, items[i], out + i * terms_);
    };
    if (threads <= 1 || count < 256) {
      some(0, count);
      return;
    }
    std::vector<std::thread> pool;
    const size_t chunk = (count + threads - 1) / threads;
    for (size_t t = 1; t < threads; ++t) {
      const size_t b = std::min(count, t * chunk);
      const size_t e = std::min(count, b + chunk);
      pool.emplace_back(some, b, e);
    }
    some(0, std::min(count, chunk));
    for (std::thread& t : pool) t.join();
  }

  // Picks the vantage point of work_[lo, hi): among a few random candidates,
  // the one whose distances to a random sample spread the most (a point
  // near the "corner" of the data splits it best; NMSLIB's heuristic).
  uint32_t ChooseVantage(uint32_t node, uint32_t lo, uint32_t hi) {
    const size_t m = hi - lo;
    const size_t candidates = options_.vantage_candidates;
    const size_t sample = options_.vantage_sample;
    // Seeded per node so the tree does not depend on thread timing.
    std::mt19937_64 rng(options_.seed * 0x9e3779b97f4a7c15ull + node);
    std::uniform_int_distribution<uint32_t> pick(lo, hi - 1);
    if (candidates <= 1 || m < 4 * sample) return pick(rng);
    std::vector<uint32_t> sampled(sample);
    for (uint32_t& s : sampled) s = work_[pick(rng)];
    std::vector<double> d(sample);
    std::vector<double> terms(sample * terms_);
    uint32_t best = lo;
    double best_spread = -1.0;
    for (size_t c = 0; c < candidates; ++c) {
      const uint32_t pos = pick(rng);
      DistancesTo(work_[pos], sampled.data(), sample, terms.data());
      for (size_t i = 0; i < sample; ++i) d[i] = Weighted(&terms[i * terms_]);
      double mean = 0.0;
      for (double v : d) mean += v;
      mean /= static_cast<double>(sample);
      double var = 0.0;
      for (double v : d) var += (v - mean) * (v - mean);
      if (var > best_spread) {
        best_spread = var;
        best = pos;
      }
    }
    return best;
  }

  // Builds the subtree over work_[lo, hi) whose items all have `depth`
  // ancestor distances in rows_. Returns its node index.
  uint32_t BuildNode(uint32_t parent, uint32_t depth, uint32_t lo,
                     uint32_t hi) {
    const uint32_t index = static_cast<uint32_t>(data_->nodes.size());
    data_->nodes.emplace_back();
    {
      VpTree::Node& node = data_->nodes.back();
      node.parent = parent;
      node.depth = depth;
      node.range_offset = data_->ranges.size();
    }
    data_->height = std::max<size_t>(data_->height, depth);
    for (uint32_t a = 0; a < depth * terms_; ++a) {
      double mn = std::numeric_limits<double>::infinity();
      double mx = 0.0;
      for (uint32_t p = lo; p < hi; ++p) {
        const double v = rows_[work_[p]][a];
        mn = std::min(mn, v);
        mx = std::max(mx, v);
      }
      data_->ranges.push_back(mn);
      data_->ranges.push_back(mx);
    }
    if (Cancelled()) return index;
    if (hi - lo <= options_.leaf_size) {
      VpTree::Node& node = data_->nodes[index];
      node.begin = static_cast<uint32_t>(data_->leaf_items.size());
      for (uint32_t p = lo; p < hi; ++p) {
        data_->leaf_items.push_back(work_[p]);
        data_->item_holder[work_[p]] = index;
      }
      node.end = static_cast<uint32_t>(data_->leaf_items.size());
      return index;
    }
    const uint32_t pos = ChooseVantage(index, lo, hi);
    std::swap(work_[lo], work_[pos]);
    const uint32_t vp = work_[lo];
    data_->item_holder[vp] = index;
    const size_t m = hi - lo - 1;
    std::vector<double> d(m * terms_);
    DistancesTo(vp, &work_[lo + 1], m, d.data());
    std::vector<std::pair<double, uint32_t>> order(m);
    for (size_t i = 0; i < m; ++i) {
      const uint32_t item = work_[lo + 1 + i];
      const double* terms = &d[i * terms_];
      rows_[item].insert(rows_[item].end(), terms, terms + terms_);
      order[i] = {Weighted(terms), item};
    }
    // Median split; (distance, item) keeps it deterministic under ties. The
    // stored ranges, not the split rule, carry correctness.
    std::sort(order.begin(), order.end());
    for (size_t i = 0; i < m; ++i) work_[lo + 1 + i] = order[i].second;
    const uint32_t mid = lo + 1 + static_cast<uint32_t>(m / 2);
    uint32_t inner = kNone;
    uint32_t outer = kNone;
    if (mid > lo + 1) inner = BuildNode(index, depth + 1, lo + 1, mid);
    if (hi > mid) outer = BuildNode(index, depth + 1, mid, hi);
    VpTree::Node& node = data_->nodes[index];
    node.vp = vp;
    node.inner = inner;
    node.outer = outer;
    return index;
  }

  const size_t n_;
  const size_t terms_;
  const PairTerms& distance_;
  const TermVector build_weights_;
  const VpTreeOptions options_;
  const std::atomic<bool>* cancel_;
  bool cancelled_ = false;
  VpTree::Data* data_ = nullptr;
  // Per item: its term distances to its ancestors' vantage points, root
  // first, terms_ values per ancestor.
  std::vector<std::vector<double>> rows_;
  std::vector<uint32_t> work_;
};

absl::StatusOr<VpTree> VpTree::Build(size_t n, size_t terms,
                                     const PairTerms& distance,
                                     const TermVector& build_weights,
                                     const VpTreeOptions& options,
                                     const std::atomic<bool>* cancel) {
  return VpTreeBuilder(n, terms, distance, build_weights, options, cancel)
      .Run();
}

absl::StatusOr<VpTree> VpTree::Build(size_t n, const PairDistance& distance,
                                     const VpTreeOptions& options,
                                     const std::atomic<bool>* cancel) {
  PairTerms one;
  if (distance) {
    one = [&distance](uint32_t i, uint32_t j, double* out) {
      out[0] = distance(i, j);
    };
  }
  return Build(n, 1, one, {1.0, 0.0, 0.0}, options, cancel);
}

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
