// VP-tree build (VpTree::Build): vantage point selection, partitioning and
// the stored per-ancestor distances (layout: internal/vp_tree_data.h).
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

}  // namespace tpr::index
