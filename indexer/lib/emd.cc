// Exact EMD by a network simplex specialized for small dense transportation
// problems, and the centroid lower bound.
//
// Why hand-written. LEMON's NetworkSimplex (Boost licence, Debian
// liblemon-dev) is correct and is our test oracle, but it is generic graph
// code (arc and node maps, block-search pricing tuned for large sparse
// graphs, an all-artificial start that needs about n + m pivots just to
// build a basis); in bench_match it takes about 3.7x our time even with
// its graph built once per size.
// Rubner's emd.c keeps static state (not thread-safe) and has fixed maximum
// sizes. Here the arcs are implicit (arc (i, j) is cell (i, j) of a dense
// cost matrix computed by a vectorized kernel), the start is a greedy basis
// that is already close to optimal, and every buffer is reused.
//
// The method (network simplex for the transportation problem):
//   nodes: supplies 0..n-1 (masses of a), demands n..n+m-1 (masses of b),
//          and an artificial root R = n + m;
//   arcs:  i -> n+j for every cell, cost Dist(a_i, b_j), uncapacitated;
//          R -> v for every node, cost 0, never allowed to enter.
// The spanning tree is stored as parent pointers, depths and a thread
// (preorder successor and predecessor); the flow of the tree arc joining v to
// parent[v] is flow[v]. The direction of a tree arc follows from the node types
// (supply -> demand, root -> anything), so it is not stored.
//
// Start. A greedy assignment (least reduced cost per row, see
// InitialBasis) ships all mass along at most n + m - 1 cells, which form a
// forest (each allocation exhausts its row or its column, so no cycle can
// close). Each forest component hangs
// from R by an artificial arc R -> v of flow 0. Every zero-flow tree arc is
// therefore an artificial arc directed away from the root: the tree is
// STRONGLY FEASIBLE (Cunningham 1976).
//
// Pricing. Candidate lists: a full (vectorized) scan of the reduced costs
// keeps each column's most negative one, and pivots are taken among those
// until fewer than three are negative; only a full scan can declare
// optimality.
//
// Degeneracy and cycling. The leaving arc is chosen by Cunningham's rule:
// among the blocking arcs of the pivot cycle, the last one met when the
// cycle is traversed in the direction of the entering arc starting at the
// apex (the join of the two tree paths). This keeps the tree strongly
// feasible after every pivot, which rules out cycling whatever the entering
// rule (degenerate pivots, zero-mass features, ties and identical
// signatures included). LEMON uses the same rule.
//
// Artificial arcs never carry mass: a cycle through R uses two of them,
// and the one it traverses backwards blocks with flow 0, so such a pivot is
// degenerate (it merges two components). Hence the final flow is feasible
// for the real arcs alone, every real tree arc has reduced cost 0 and every
// other real arc has reduced cost >= -tolerance: the LP optimality
// conditions hold, so the flow is an optimal transport plan.
#include "indexer/lib/emd.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <utility>

#include "indexer/lib/internal/emd_kernels.h"
#include "indexer/lib/internal/ground_distance_kernels.h"

namespace tpr::index {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Candidate-list pricing (a major/minor scheme). A major pass scans all
// n x m reduced costs c_ij + u_i - v_j and records, for every column with
// a reduced cost below -tol, its most negative row (the first one on
// ties): the candidates. Minor passes then price only the candidates, with
// current potentials, and pivot on the most negative, until none is
// negative; then the next major pass. The first pivot of a major pass is
// Dantzig's choice; later ones cost O(m) instead of O(n m). Optimality is
// declared only by a major pass that finds no reduced cost below -tol, so
// the rule is exact. Why per column rather than per row: lanes then run
// over 8 consecutive columns of the row-major matrix, and each lane keeps
// its own minimum and row, so the pass has no horizontal reduction and no
// data-dependent branch (the per-row version, with one reduction and two
// unpredictable branches per row, cost about 2.5x more). `v` is padded to
// `cs` entries with -inf so padded columns never qualify; cand_i and
// cand_j hold cs entries. The kernels (this pass, and the start's column
// minima, row arg-min and rank order) live in internal/emd_kernels.h, in
// scalar, AVX2 and AVX-512F variants with the same values bit for bit.
const internal::EmdKernels& Kernels() {
  static const internal::EmdKernels& kernels =
      *internal::EmdKernelsFor(internal::ChosenSimdLevel());
  return kernels;
}

}  // namespace

struct EmdSolver::Impl {
  // Problem.
  int n = 0;
  int m = 0;
  int cs = 0;                // cost row stride (multiple of 8)
  std::vector<double> cost;  // n x cs
  std::vector<double> supply;
  std::vector<double> demand;

  // Tree over n + m + 1 nodes; R = n + m.
  std::vector<int> parent;
  std::vector<int> thread;      // preorder successor (circular through R)
  std::vector<int> rev_thread;  // preorder predecessor
  std::vector<double> flow;     // flow of the arc joining v and parent[v]
  std::vector<double> pi;       // potentials; u = pi[0..n), v = pi[n..n+m)
  std::vector<int> depth;       // depth[R] = 0

  // Scratch.
  std::vector<double> vpad;
  std::vector<double> rem_a;
  std::vector<int> row_order;
  std::vector<double> rem_b;
  std::vector<double> col_offset;    // cs entries: -(column minimum)
  std::vector<uint64_t> col_closed;  // bit set of closed columns
  std::vector<int> cand_i;  // pricing candidates (one per column at most)
  std::vector<int> cand_j;
  std::vector<int> cell_i;
  std::vector<int> cell_j;
  std::vector<double> cell_f;
  std::vector<int> adj_start;
  std::vector<int> adj_fill;
  std::vector<int> adj;
  std::vector<int> queue;
  std::vector<int> piece_a_last;   // pivot: last node of A_k (stem k)
  std::vector<int> piece_b_first;  // pivot: first node of B_k
  std::vector<int> piece_b_last;   // pivot: last node of B_k, -1 if empty
  std::vector<int> path1;
  std::vector<int> path2;
  std::vector<unsigned char> closed;  // ConstrainedBound: entries used
  std::vector<float> cost32;  // ConstrainedBound32's matrix (not `cost`)

  EmdStats stats;
  double max_cost = 0.0;  // upper bound of the cost entries
  // Serials of the pair whose ground-distance matrix `cost` holds (0: none).
  uint64_t matrix_a = 0;
  uint64_t matrix_b = 0;

  // Fills cost (and max_cost, supply, demand) for the pair, unless it holds
  // that pair's matrix already. Solve only reads cost, so the matrix stays
  // valid after a solve.
  void Load(const PreparedSignature& a, const PreparedSignature& b) {
    n = a.size();
    m = b.size();
    cs = b.stride();
    Reserve(n, m, cs);
    if (a.serial() == 0 || a.serial() != matrix_a || b.serial() != matrix_b) {
      max_cost = GroundDistanceMatrix(a, b, cost.data(), cs);
      matrix_a = a.serial();
      matrix_b = b.serial();
    }
    for (int i = 0; i < n; ++i) supply[i] = a.weight(i);
    for (int j = 0; j < m; ++j) demand[j] = b.weight(j);
  }

  void Reserve(int nn, int mm, int stride) {
    const size_t nodes = static_cast<size_t>(nn + mm + 1);
    const size_t cells = static_cast<size_t>(nn) * static_cast<size_t>(stride);
    if (cost.size() < cells) cost.resize(cells);
    if (supply.size() < static_cast<size_t>(nn)) supply.resize(nn);
    if (demand.size() < static_cast<size_t>(mm)) demand.resize(mm);
    if (rem_a.size() < static_cast<size_t>(nn)) {
      rem_a.resize(nn);
      row_order.resize(nn);
    }
    if (rem_b.size() < static_cast<size_t>(mm)) {
      rem_b.resize(mm);
    }
    if (vpad.size() < static_cast<size_t>(stride)) {
      vpad.resize(stride);
      cand_i.resize(stride);
      cand_j.resize(stride);
      col_offset.resize(stride);
      col_closed.resize((stride + 63) / 64);
    }
    if (parent.size() < nodes) {
      parent.resize(nodes);
      thread.resize(nodes);
      rev_thread.resize(nodes);
      piece_a_last.resize(nodes);
      piece_b_first.resize(nodes);
      piece_b_last.resize(nodes);
      flow.resize(nodes);
      pi.resize(nodes);
      depth.resize(nodes);
      cell_i.resize(nodes);
      cell_j.resize(nodes);
      cell_f.resize(nodes);
      adj_start.resize(nodes + 1);
      adj_fill.resize(nodes + 1);
      adj.resize(2 * nodes);
      queue.resize(nodes);
      path1.resize(nodes);
      path2.resize(nodes);
      closed.resize(nodes);
    }
  }

  // Potential of v from its parent: pi[head] = pi[tail] + cost(tail, head)
  // on every tree arc (reduced cost 0), 0 below R (artificial arcs cost 0).
  double PotentialFromParent(int v) const {
    const int p = parent[v];
    if (p == n + m) return 0.0;
    if (p < n) {  // arc p -> v, v a demand node
      return pi[p] + cost[static_cast<size_t>(p) * cs + (v - n)];
    }
    // arc v -> p, v a supply node
    return pi[p] - cost[static_cast<size_t>(v) * cs + (p - n)];
  }

  void InitialBasis();
  void Pivot(int ei, int ej, double rc);
  double Solve();
};

// Initial basis (least reduced cost per row, below). The allocated cells
// form a forest (see the top comment). Masses below kDust left over from
// rounding (the two totals agree only to ~1e-16) are dropped, which changes the
// cost by less than kDust x the largest cost.
void EmdSolver::Impl::InitialBasis() {
  constexpr double kDust = 1e-14;
  const int root = n + m;
  for (int v = 0; v <= root; ++v) {
    parent[v] = -1;
    flow[v] = 0.0;
  }
  for (int i = 0; i < n; ++i) rem_a[i] = supply[i];
  for (int j = 0; j < m; ++j) rem_b[j] = demand[j];
  int cells = 0;
  // Least reduced cost per row. With v_j the smallest cost of column j,
  // every row in turn ships its mass to its open columns in increasing
  // order of c_ij - v_j (the cheapest column first, judged relative to what
  // the column could get from its best row). Measured against Vogel's
  // approximation and plain least cost per row (pivots / CPU us on
  // BM_Emd's data at n = m = 10, 30, 60): Vogel 11 / 51 / 122 pivots at
  // 3.5 / 33 / 116 us, plain row minimum 11 / 70 / 162 at 3.8 / 35 / 125,
  // this 10 / 56 / 140 at 3.9 / 30 / 112 before the vectorized argmin:
  // Vogel's plans need fewer pivots but its line choices cost more than
  // the pivots they save.
  double* offset = col_offset.data();
  uint64_t* closed_cols = col_closed.data();
  Kernels().column_min(cost.data(), cs, n, offset);
  for (int w = 0; w < (cs + 63) / 64; ++w) closed_cols[w] = 0;
  int open_cols = 0;
  for (int j = 0; j < cs; ++j) {
    const bool open = j < m && rem_b[j] > kDust;
    offset[j] = -offset[j];
    closed_cols[j >> 6] |= static_cast<uint64_t>(!open) << (j & 63);
    open_cols += open;
  }
  // Columns 0..63 are tracked in a register from here on (RowArgMin).
  uint64_t closed_lo = closed_cols[0];
  const internal::RowArgMinFn row_arg_min = Kernels().row_arg_min;
  // Rows go in increasing order of mass: small rows take their best
  // columns whole and leave the large rows to spread over what is left,
  // which measured 8% fewer pivots than index order at n = m = 30 (ties
  // by index; RankOrder).
  int* order = row_order.data();
  Kernels().rank_order(rem_a.data(), n, order);
  for (int oi = 0; oi < n && open_cols > 0; ++oi) {
    const int i = order[oi];
    while (rem_a[i] > kDust && open_cols > 0) {
      const int bj = row_arg_min(&cost[static_cast<size_t>(i) * cs], offset,
                                 closed_lo, closed_cols, cs);
      const double f = std::min(rem_a[i], rem_b[bj]);
      rem_a[i] -= f;
      rem_b[bj] -= f;
      cell_i[cells] = i;
      cell_j[cells] = bj;
      cell_f[cells] = f;
      ++cells;
      if (rem_b[bj] <= kDust) {
        if (bj < 64) {
          closed_lo |= uint64_t{1} << bj;
        } else {
          closed_cols[bj >> 6] |= uint64_t{1} << (bj & 63);
        }
        --open_cols;
      }
    }
  }
  assert(cells <= n + m - 1);
  // Forest adjacency (CSR), then orientation by BFS from each component's
  // first node, which hangs from R by a zero-flow artificial arc.
  for (int v = 0; v <= root + 1; ++v) adj_start[v] = 0;
  for (int c = 0; c < cells; ++c) {
    ++adj_start[cell_i[c] + 1];
    ++adj_start[n + cell_j[c] + 1];
  }
  for (int v = 0; v <= root; ++v) adj_start[v + 1] += adj_start[v];
  for (int v = 0; v <= root; ++v) adj_fill[v] = adj_start[v];
  for (int c = 0; c < cells; ++c) {
    adj[adj_fill[cell_i[c]]++] = c;
    adj[adj_fill[n + cell_j[c]]++] = c;
  }
  // Depth-first from each component's first node, so that the visiting
  // order is a preorder: it becomes the thread. A node's parent, flow,
  // potential and depth are set when it is pushed (the forest is acyclic,
  // so a node is reached only from its parent).
  pi[root] = 0.0;
  depth[root] = 0;
  int last = root;  // last node of the thread so far
  for (int s = 0; s < root; ++s) {
    if (parent[s] != -1) continue;
    parent[s] = root;
    pi[s] = 0.0;
    depth[s] = 1;
    int top = 0;
    queue[top++] = s;
    while (top > 0) {
      const int v = queue[--top];
      thread[last] = v;
      rev_thread[v] = last;
      last = v;
      for (int k = adj_start[v]; k < adj_start[v + 1]; ++k) {
        const int c = adj[k];
        const int w = (v < n) ? n + cell_j[c] : cell_i[c];
        if (parent[w] != -1) continue;  // v's parent (acyclic: no other)
        parent[w] = v;
        flow[w] = cell_f[c];
        pi[w] = PotentialFromParent(w);
        depth[w] = depth[v] + 1;
        queue[top++] = w;
      }
    }
  }
  thread[last] = root;
  rev_thread[root] = last;
}

// One pivot on entering arc ei -> n + ej, whose reduced cost rc < 0.
void EmdSolver::Impl::Pivot(int ei, int ej, double rc) {
  const int root = n + m;
  const int first = ei;
  const int second = n + ej;

  // Leaving arc by Cunningham's rule (see the top comment). The cycle runs
  // join -> ... -> first -> second -> ... -> join. On the first path an arc
  // is traversed downwards, so it is backward (blocking) when it points up:
  // a supply node below a demand node. On the second path an arc is
  // traversed upwards, so it blocks when it points down: a demand node
  // (below a supply node or R) or an artificial arc. Ties: on the first
  // path the arc nearest `first` wins (strict <), on the second path the
  // arc nearest the apex (<=), and the second path wins over the first:
  // the last blocking arc in cycle order.
  // The deeper end climbs to the other's depth, then both climb in step
  // until they meet at the apex: the loops' branches are predictable
  // (which side is deeper at each step is not).
  double delta1 = kInf;
  int out1 = -1;  // index in path1
  double delta2 = kInf;
  int out2 = -1;  // index in path2
  int len1 = 0;
  int len2 = 0;
  int v1 = first;
  int v2 = second;
  auto step1 = [&] {
    if (v1 < n && parent[v1] != root && flow[v1] < delta1) {
      delta1 = flow[v1];
      out1 = len1;
    }
    path1[len1++] = v1;
    v1 = parent[v1];
  };
  auto step2 = [&] {
    if ((v2 >= n || parent[v2] == root) && flow[v2] <= delta2) {
      delta2 = flow[v2];
      out2 = len2;
    }
    path2[len2++] = v2;
    v2 = parent[v2];
  };
  for (int d = depth[v1] - depth[v2]; d > 0; --d) step1();
  for (int d = depth[v2] - depth[v1]; d > 0; --d) step2();
  while (v1 != v2) {
    step1();
    step2();
  }
  const bool out_on_first = !(out2 >= 0 && delta2 <= delta1);
  const double delta = out_on_first ? delta1 : delta2;
  assert((out_on_first ? out1 : out2) >= 0);
  ++stats.pivots;
  if (delta > 0.0) {
    // No artificial arc lies on a cycle that moves mass (see the top
    // comment), so every arc below is real.
    for (int k = 0; k < len1; ++k) {
      const int v = path1[k];
      flow[v] += (v < n) ? -delta : delta;
    }
    for (int k = 0; k < len2; ++k) {
      const int v = path2[k];
      flow[v] += (v >= n) ? -delta : delta;
    }
  } else {
    ++stats.degenerate_pivots;
  }

  // Re-hang the subtree cut off by the leaving arc: s is the entering arc's
  // endpoint inside it, t the other endpoint. Parent links along s..u_out
  // (a prefix of the recorded path) reverse, and each arc's flow moves to
  // its new child endpoint.
  const int s = out_on_first ? first : second;
  const int t = out_on_first ? second : first;
  const int* path = out_on_first ? path1.data() : path2.data();
  const int len = (out_on_first ? out1 : out2) + 1;
  double carried = delta;  // flow of the entering arc
  for (int k = 0; k < len; ++k) {
    const int v = path[k];
    const double old = flow[v];
    parent[v] = k == 0 ? t : path[k - 1];
    flow[v] = carried;
    carried = old;
  }
  // The thread (preorder) is rebuilt for the moved subtree only. Old
  // preorder: the subtree of u_out = path[len - 1] is one run in which the
  // subtrees of the stem nodes path[0] = s, path[1], ... are nested runs.
  // Re-rooted at s and hung below t, its preorder is s's old run, then for
  // k = 1, 2, ...: path[k]'s old run minus path[k - 1]'s, in two pieces:
  // A_k (from path[k] up to path[k - 1]) and B_k (after path[k - 1]'s run
  // up to the end of path[k]'s). Each piece keeps its internal order, so
  // its internal thread links stay valid and only the links between pieces
  // change (O(len)). The old run is A_{len-1} ... A_1, s's run, B_1 ...
  // B_{len-1}: one walk along it shifts each piece's depths by its own
  // amount (stem node k goes from depth d_out + len - 1 - k to
  // depth[t] + 1 + k) and every potential by the amount that zeroes the
  // entering arc's reduced cost rc = c + pi_i - pi_j: -rc if the supply
  // end moved, +rc if the demand end did. The walk reads each node's old
  // depth before updating it. Then the pieces are spliced right after t.
  // O(subtree) with no recursion, no copy and no per-child branching.
  const double shift = out_on_first ? -rc : rc;
  const int u_out = path[len - 1];
  const int d_out = depth[u_out];
  const int dd0 = depth[t] + 1 - (d_out + len - 1);  // depth shift of s
  const int before = rev_thread[u_out];
  int* a_last = piece_a_last.data();
  int* b_first = piece_b_first.data();
  int* b_last = piece_b_last.data();
  for (int k = len - 1; k >= 1; --k) {  // A_k: ends where path[k - 1] is
    const int dd = dd0 + 2 * k;
    const int stop = path[k - 1];
    int x = path[k];
    int last;
    do {
      pi[x] += shift;
      depth[x] += dd;
      last = x;
      x = thread[x];
    } while (x != stop);
    a_last[k] = last;
  }
  int x = s;
  int s_last;
  {
    const int ds = d_out + len - 1;  // s's old depth
    do {
      pi[x] += shift;
      depth[x] += dd0;
      s_last = x;
      x = thread[x];
    } while (depth[x] > ds);
  }
  for (int k = 1; k < len; ++k) {  // B_k: deeper than path[k] (old)
    const int dk = d_out + len - 1 - k;
    const int dd = dd0 + 2 * k;
    int last = -1;  // B_k empty
    b_first[k] = x;
    while (depth[x] > dk) {
      pi[x] += shift;
      depth[x] += dd;
      last = x;
      x = thread[x];
    }
    b_last[k] = last;
  }
  const int after = x;
  thread[before] = after;
  rev_thread[after] = before;
  int prev = t;
  const int next = thread[t];
  auto link = [&](int from, int to) {
    thread[prev] = from;
    rev_thread[from] = prev;
    prev = to;
  };
  link(s, s_last);
  for (int k = 1; k < len; ++k) {
    link(path[k], a_last[k]);
    if (b_last[k] >= 0) link(b_first[k], b_last[k]);
  }
  thread[prev] = next;
  rev_thread[next] = prev;
}

double EmdSolver::Impl::Solve() {
  stats = EmdStats{};
  const int root = n + m;
  InitialBasis();
  const double tol = 1e-12 * std::max(max_cost, 1e-300);
  // Safety net against a floating-point stall; never reached in tests (the
  // strongly feasible tree excludes cycling in exact arithmetic).
  const int64_t max_pivots = 1000 + 50LL * (n + m) * (n + m);
  for (int j = m; j < cs; ++j) vpad[j] = -kInf;
  const internal::CollectFn collect = Kernels().collect;
  int candidates = 0;
  bool fresh = false;  // no pivot since the last major pass
  while (stats.pivots < max_pivots) {
    // Minor pass over the candidates.
    // Candidates whose reduced cost is no longer below -tol are dropped
    // (the pivot just taken among them: its reduced cost is now 0); a
    // dropped one that turns negative again is found by the next major
    // pass. Selects, not branches: the comparisons are unpredictable.
    double best = -tol;
    int pick = -1;
    int kept = 0;
    for (int c = 0; c < candidates; ++c) {
      const int i = cand_i[c];
      const int j = cand_j[c];
      const double rc =
          (cost[static_cast<size_t>(i) * cs + j] + pi[i]) - pi[n + j];
      cand_i[kept] = i;
      cand_j[kept] = j;
      const bool lt = rc < best;
      best = lt ? rc : best;
      pick = lt ? kept : pick;
      kept += rc < -tol;
    }
    candidates = kept;
    // A major pass also runs early when fewer than kMinCandidates are left
    // (but never twice without a pivot in between, so every major pass
    // that finds candidates is followed by a pivot): a fresh Dantzig choice
    // beats the last few stale candidates. Measured at n = m = 30: 45
    // instead of 50 pivots and about 4% less time; at 60 no change.
    constexpr int kMinCandidates = 3;
    if (pick < 0 || (candidates < kMinCandidates && !fresh)) {
      fresh = true;
      // Major pass.
      for (int j = 0; j < m; ++j) vpad[j] = pi[n + j];
      candidates = collect(cost.data(), cs, n, pi.data(), vpad.data(), tol,
                           cand_i.data(), cand_j.data());
      if (candidates == 0) break;  // optimal
      continue;
    }
    fresh = false;
    Pivot(cand_i[pick], cand_j[pick], best);
  }
  assert(stats.pivots < max_pivots);
  double total = 0.0;
  double moved = 0.0;
  for (int v = 0; v < root; ++v) {
    const int p = parent[v];
    if (p == root || flow[v] == 0.0) continue;
    const int i = v < n ? v : p;
    const int j = (v < n ? p : v) - n;
    total += flow[v] * cost[static_cast<size_t>(i) * cs + j];
    moved += flow[v];
  }
  return moved > 0.0 ? total / moved : 0.0;
}

EmdSolver::EmdSolver() : impl_(new Impl) {}
EmdSolver::~EmdSolver() { delete impl_; }
EmdSolver::EmdSolver(EmdSolver&& other) noexcept : impl_(other.impl_) {
  other.impl_ = nullptr;
}
EmdSolver& EmdSolver::operator=(EmdSolver&& other) noexcept {
  std::swap(impl_, other.impl_);
  return *this;
}

EmdSolver::Impl& EmdSolver::LoadPair(const PreparedSignature& a,
                                     const PreparedSignature& b) {
  assert(a.size() >= 1 && a.size() <= kMaxFeatures);
  assert(b.size() >= 1 && b.size() <= kMaxFeatures);
  if (impl_ == nullptr) impl_ = new Impl;
  impl_->Load(a, b);
  return *impl_;
}

double EmdSolver::Distance(const PreparedSignature& a,
                           const PreparedSignature& b) {
  return LoadPair(a, b).Solve();
}

// Relaxed transport bound (Kusner et al. 2015). Any feasible plan f has row
// sums w_i, and f_ij Dist(a_i, b_j) >= f_ij min_j' Dist(a_i, b_j') because
// f_ij >= 0, so
//   sum_ij f_ij Dist(a_i, b_j) >= sum_i (sum_j f_ij) min_j Dist(a_i, b_j)
//                               = sum_i w_i min_j Dist(a_i, b_j);
// the same holds by columns. Both hold for the optimal plan, whose cost is
// the EMD, hence so does their maximum. No property of Dist is needed
// beyond non-negativity of the flow; equal total masses make both sides
// plans of the same problem.
double EmdSolver::RelaxedBound(const PreparedSignature& a,
                               const PreparedSignature& b) {
  Impl& s = LoadPair(a, b);
  constexpr double kInfCost = std::numeric_limits<double>::infinity();
  // Column minima accumulate row by row (a row-major matrix: contiguous).
  double* col_min = s.rem_b.data();  // scratch of m entries, free here
  for (int j = 0; j < s.m; ++j) col_min[j] = kInfCost;
  double rows = 0.0;
  for (int i = 0; i < s.n; ++i) {
    const double* row = s.cost.data() + static_cast<size_t>(i) * s.cs;
    double row_min = kInfCost;
    for (int j = 0; j < s.m; ++j) {
      row_min = std::min(row_min, row[j]);
      col_min[j] = std::min(col_min[j], row[j]);
    }
    rows += s.supply[i] * row_min;
  }
  double cols = 0.0;
  for (int j = 0; j < s.m; ++j) cols += s.demand[j] * col_min[j];
  return std::max(rows, cols);
}

// Capacity-constrained relaxed transport bound (the "ICT" bound of Atasu
// and Mittelholzer 2019, "Linear-complexity data-parallel Earth Mover's
// Distance approximations", ICML). Any feasible plan f has, besides f_ij >=
// 0 and row sums w_i, f_ij <= sum_i' f_i'j = w'_j. So row i of f is a
// feasible point of
//   R_i = min { sum_j g_j Dist(a_i, b_j) : sum_j g_j = w_i, 0 <= g_j <= w'_j }
// and sum_ij f_ij Dist(a_i, b_j) >= sum_i R_i; likewise by columns, with
// capacities w_i. Both hold for the optimal plan, whose cost is the EMD,
// hence so does their maximum. R_i is a fractional knapsack: filling the
// cheapest columns first, each up to its capacity, is optimal (moving mass
// from a dearer column to a cheaper one with room never costs more). Each
// unit of w_i costs at least the row's minimum, so R_i >= w_i min_j
// Dist(a_i, b_j): the bound is never below the relaxed transport bound,
// and it is its equal where every feature's nearest partner can take all
// of its mass. Should the capacities run out first (the totals are 1 only
// to about 1e-16), the rest is left unshipped, which only lowers the sum.
namespace {

// CheapestFirst returns the sum over `lines` lines of the cost matrix
// (entry k of line l at cost[l * line_step + k * entry_step], k < entries)
// of the cheapest way to ship mass[l] into the entries with capacities
// cap[k], cheapest entry first (R_i above). closed: scratch of `entries`.
// T: double, or float for the float32 matrix (ConstrainedBound32); the
// sums are in double either way.
template <typename T>
double CheapestFirst(const T* cost, size_t line_step, size_t entry_step,
                     int lines, int entries, const double* mass,
                     const double* cap, unsigned char* closed) {
  double total = 0.0;
  for (int l = 0; l < lines; ++l) {
    const T* line = cost + static_cast<size_t>(l) * line_step;
    int best = 0;
    double best_cost = line[0];
    for (int k = 1; k < entries; ++k) {
      const double c = line[static_cast<size_t>(k) * entry_step];
      best = c < best_cost ? k : best;
      best_cost = c < best_cost ? c : best_cost;
    }
    double left = mass[l];
    if (left <= cap[best]) {  // the usual case: the nearest entry holds it
      total += left * best_cost;
      continue;
    }
    std::fill(closed, closed + entries, 0);
    double sum = 0.0;
    while (true) {
      closed[best] = 1;
      const double take = std::min(left, cap[best]);
      sum += take * best_cost;
      left -= take;
      if (!(left > 0.0)) break;
      best = -1;
      best_cost = kInf;
      for (int k = 0; k < entries; ++k) {
        const double c = line[static_cast<size_t>(k) * entry_step];
        if (closed[k] == 0 && c < best_cost) {
          best = k;
          best_cost = c;
        }
      }
      if (best < 0) break;  // every capacity used: the rest is rounding
    }
    total += sum;
  }
  return total;
}

}  // namespace

double EmdSolver::ConstrainedBound(const PreparedSignature& a,
                                   const PreparedSignature& b) {
  Impl& s = LoadPair(a, b);
  const double rows =
      CheapestFirst(s.cost.data(), static_cast<size_t>(s.cs), 1, s.n, s.m,
                    s.supply.data(), s.demand.data(), s.closed.data());
  const double cols =
      CheapestFirst(s.cost.data(), 1, static_cast<size_t>(s.cs), s.m, s.n,
                    s.demand.data(), s.supply.data(), s.closed.data());
  return std::max(rows, cols);
}

// The float32 form. With c~ the float32 matrix and theta =
// Float32MatrixError(bands), every entry has c~ <= (1 + theta) c
// (ground_distance.h). The bound is a minimum over the same feasible
// plans g >= 0 of the linear cost sum g c (a maximum of two such minima),
// with coefficients g >= 0, so it is monotone in the entries and
// positively homogeneous: ICT(c~) <= ICT((1 + theta) c) = (1 + theta)
// ICT(c). Hence ICT(c~) / (1 + theta) <= ICT(c) <= EMD; and it is below
// ICT(c) by at most 2 theta / (1 + theta) of it (c~ >= (1 - theta) c).
// The greedy sums run in double on the float32 entries, as the double form
// does on its entries.
double EmdSolver::ConstrainedBound32(const PreparedSignature& a,
                                     const PreparedSignature& b) {
  assert(a.size() >= 1 && a.size() <= kMaxFeatures);
  assert(b.size() >= 1 && b.size() <= kMaxFeatures);
  if (impl_ == nullptr) impl_ = new Impl;
  Impl& s = *impl_;
  const int stride = internal::Stride32(b);
  const size_t cells = static_cast<size_t>(a.size()) * stride;
  if (s.cost32.size() < cells) s.cost32.resize(cells);
  const size_t lines = static_cast<size_t>(std::max(a.size(), b.size()));
  if (s.closed.size() < lines) s.closed.resize(lines);
  if (!internal::GroundDistanceMatrix32(a, b, s.cost32.data(), stride)) {
    return ConstrainedBound(a, b);
  }
  const double rows =
      CheapestFirst(s.cost32.data(), static_cast<size_t>(stride), 1, a.size(),
                    b.size(), a.weights(), b.weights(), s.closed.data());
  const double cols =
      CheapestFirst(s.cost32.data(), 1, static_cast<size_t>(stride), b.size(),
                    a.size(), b.weights(), a.weights(), s.closed.data());
  return std::max(rows, cols) / (1.0 + internal::Float32MatrixError(a.bands()));
}

const EmdStats& EmdSolver::Stats() const { return impl_->stats; }

std::vector<EmdSolver::FlowEntry> EmdSolver::LastFlow() const {
  std::vector<FlowEntry> out;
  const Impl& s = *impl_;
  const int root = s.n + s.m;
  for (int v = 0; v < root; ++v) {
    const int p = s.parent[v];
    if (p == root || s.flow[v] <= 0.0) continue;
    const int i = v < s.n ? v : p;
    const int j = (v < s.n ? p : v) - s.n;
    out.push_back({i, j, s.flow[v]});
  }
  return out;
}

namespace {
EmdSolver& ThreadSolver() {
  thread_local EmdSolver solver;
  return solver;
}
}  // namespace

double Emd(const PreparedSignature& a, const PreparedSignature& b) {
  return ThreadSolver().Distance(a, b);
}

double RelaxedTransportBound(const PreparedSignature& a,
                             const PreparedSignature& b) {
  return ThreadSolver().RelaxedBound(a, b);
}

double ConstrainedTransportBound(const PreparedSignature& a,
                                 const PreparedSignature& b) {
  return ThreadSolver().ConstrainedBound(a, b);
}

double ConstrainedTransportBound32(const PreparedSignature& a,
                                   const PreparedSignature& b) {
  return ThreadSolver().ConstrainedBound32(a, b);
}

void PrefetchSignature(const PreparedSignature& p) {
#if defined(__GNUC__)
  const char* block = reinterpret_cast<const char*>(p.weights());
  const size_t lines = (p.MemoryBytes() + 63) / 64;
  // Locality 2 (x86 prefetcht1: into L2, not L1): about 54 lines at once
  // would overflow the L1 miss queue; the matrix kernel reads them from L2
  // in a few cycles each.
  for (size_t line = 0; line < lines; ++line)
    __builtin_prefetch(block + 64 * line, 0, 2);
#else
  (void)p;
#endif
}

// Centroid bound (Rubner et al. [22], section 4.3). With phi and the norm N
// of ground_distance.h, Dist(x, y) = N(phi(x) - phi(y)). Let f be any
// feasible plan: f_ij >= 0, sum_j f_ij = w_i, sum_i f_ij = w'_j, and
// sum_ij f_ij = 1 (equal total masses, both 1). Then
//   centroid(a) - centroid(b) = sum_i w_i phi(a_i) - sum_j w'_j phi(b_j)
//                             = sum_ij f_ij (phi(a_i) - phi(b_j)),
// and by the triangle inequality and homogeneity of the norm N,
//   N(centroid(a) - centroid(b)) <= sum_ij f_ij N(phi(a_i) - phi(b_j))
//                                 = sum_ij f_ij Dist(a_i, b_j).
// This holds for every plan, so also for the optimal one, whose cost is the
// EMD (total flow 1, so no normalization). Equal masses are essential: with
// unequal totals the first equality fails.
namespace {

// Row r of the centroid of p: sum_i w_i phi32(U_i)_r in double. The
// products of a double weight and a float32 coordinate are summed in
// feature order.
double CentroidRow(const PreparedSignature& p, int r) {
  const int n = p.size();
  const float* x = p.coords() + static_cast<size_t>(r) * static_cast<size_t>(n);
  const double* w = p.weights();
  double c = 0.0;
  for (int i = 0; i < n; ++i) c += w[i] * static_cast<double>(x[i]);
  return c;
}

// Accessors of internal::CentroidNorm (emd.h) over a raw centroid and
// over one computed on the fly.
auto RawCentroid(const double* c, int bands) {
  return [c, bands](int block, int d) {
    return c[block < 0 ? 0 : 1 + block * bands + d];
  };
}
auto LiveCentroid(const PreparedSignature& p) {
  return [&p](int block, int d) {
    return CentroidRow(p, block < 0 ? 0 : 1 + block * p.bands() + d);
  };
}

}  // namespace

double CentroidBound(const double* ca, int ba, const double* cb, int bb) {
  return internal::CentroidNorm(RawCentroid(ca, ba), ba, RawCentroid(cb, bb),
                                bb);
}

double EmdLowerBound(const PreparedSignature& a, const PreparedSignature& b) {
  return internal::CentroidNorm(LiveCentroid(a), a.bands(), LiveCentroid(b),
                                b.bands());
}

double EmdLowerBound(const double* a_centroid, int a_bands,
                     const PreparedSignature& b) {
  return internal::CentroidNorm(RawCentroid(a_centroid, a_bands), a_bands,
                                LiveCentroid(b), b.bands());
}

std::vector<double> Centroid(const PreparedSignature& p) {
  std::vector<double> c(static_cast<size_t>(p.rows()));
  for (int r = 0; r < p.rows(); ++r)
    c[static_cast<size_t>(r)] = CentroidRow(p, r);
  return c;
}

}  // namespace tpr::index
