// Exact EMD by a network simplex specialized for small dense transportation
// problems, and the centroid lower bound.
//
// Why hand-written. LEMON's NetworkSimplex (Boost licence, Debian
// liblemon-dev) is correct and is our test oracle, but it is generic graph
// code (arc and node maps, block-search pricing tuned for large sparse
// graphs, an all-artificial start that needs about n + m pivots just to
// build a basis); in bench_match it takes about twice our time even with
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
// The spanning tree is stored as parent pointers plus intrusive child
// lists; the flow of the tree arc joining v to parent[v] is flow[v]. The
// direction of a tree arc follows from the node types (supply -> demand,
// root -> anything), so it is not stored.
//
// Start. A greedy assignment (Vogel's approximation, or least cost per row
// for problems under 600 cells) ships all mass along at most n + m - 1
// cells, which form a forest (each allocation exhausts its row or its
// column, so no cycle can close). Each forest component hangs
// from R by an artificial arc R -> v of flow 0. Every zero-flow tree arc is
// therefore an artificial arc directed away from the root: the tree is
// STRONGLY FEASIBLE (Cunningham 1976).
//
// Pricing. Candidate lists: a full (vectorized) scan of the reduced costs
// keeps each row's most negative one, and pivots are taken among those
// until none is negative; only a full scan can declare optimality.
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

#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

namespace tpr::index {
namespace {


constexpr double kInf = std::numeric_limits<double>::infinity();

// Candidate-list pricing (a major/minor scheme). A major pass scans all
// n x m reduced costs c_ij + u_i - v_j and records, for every row with a
// negative one, its most negative column: the candidates. Minor passes
// then price only the candidates, with current potentials, and pivot on
// the most negative, until none is negative; then the next major pass. The
// first pivot of a major pass is Dantzig's choice; later ones cost O(n)
// instead of O(n m). Optimality is declared only by a major pass that finds
// no negative reduced cost, so the rule is exact. `v` is padded to `cs`
// entries with -inf so padded columns never qualify.
int CollectScalar(const double* cost, int cs, int n, const double* u,
                  const double* v, double tol, int* cand_i, int* cand_j) {
  int count = 0;
  for (int i = 0; i < n; ++i) {
    const double* row = cost + static_cast<size_t>(i) * cs;
    const double ui = u[i];
    double lm[8] = {kInf, kInf, kInf, kInf, kInf, kInf, kInf, kInf};
    for (int j0 = 0; j0 < cs; j0 += 8) {
      for (int l = 0; l < 8; ++l) {
        const double r = (row[j0 + l] + ui) - v[j0 + l];
        lm[l] = r < lm[l] ? r : lm[l];
      }
    }
    double rmin = lm[0];
    for (int l = 1; l < 8; ++l) rmin = lm[l] < rmin ? lm[l] : rmin;
    if (rmin < -tol) {
      for (int j = 0; j < cs; ++j) {
        if ((row[j] + ui) - v[j] == rmin) {
          cand_i[count] = i;
          cand_j[count] = j;
          ++count;
          break;
        }
      }
    }
  }
  return count;
}

#if defined(__GNUC__) && defined(__x86_64__)
#define TPR_HAVE_X86_PRICING 1
// Why intrinsics: pricing is the hot loop of the simplex and the build's
// baseline is SSE2. GCC 12's avx512fintrin.h trips -Wmaybe-uninitialized
// on its own _mm512_undefined_pd (a known false positive).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
__attribute__((target("avx512f"))) int CollectAvx512(
    const double* cost, int cs, int n, const double* u, const double* v,
    double tol, int* cand_i, int* cand_j) {
  int count = 0;
  const __m512d neg_tol = _mm512_set1_pd(-tol);
  for (int i = 0; i < n; ++i) {
    const double* row = cost + static_cast<size_t>(i) * cs;
    const __m512d ui = _mm512_set1_pd(u[i]);
    __m512d mn = _mm512_set1_pd(kInf);
    for (int j0 = 0; j0 < cs; j0 += 8) {
      const __m512d r = _mm512_sub_pd(
          _mm512_add_pd(_mm512_loadu_pd(row + j0), ui), _mm512_loadu_pd(v + j0));
      mn = _mm512_min_pd(mn, r);
    }
    if (_mm512_cmp_pd_mask(mn, neg_tol, _CMP_LT_OQ) == 0) continue;
    const __m512d rmin = _mm512_set1_pd(_mm512_reduce_min_pd(mn));
    for (int j0 = 0; j0 < cs; j0 += 8) {
      const __m512d r = _mm512_sub_pd(
          _mm512_add_pd(_mm512_loadu_pd(row + j0), ui), _mm512_loadu_pd(v + j0));
      const __mmask8 hit = _mm512_cmp_pd_mask(r, rmin, _CMP_EQ_OQ);
      if (hit != 0) {
        cand_i[count] = i;
        cand_j[count] = j0 + __builtin_ctz(static_cast<unsigned>(hit));
        ++count;
        break;
      }
    }
  }
  return count;
}
#pragma GCC diagnostic pop
#endif

using CollectFn = int (*)(const double*, int, int, const double*,
                          const double*, double, int*, int*);

CollectFn PickCollect() {
#ifdef TPR_HAVE_X86_PRICING
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f")) return CollectAvx512;
#endif
  return CollectScalar;
}

// ArgMax returns the first index of the largest of v[0..len), len a
// positive multiple of 8, no NaN.
int ArgMaxScalar(const double* v, int len) {
  int best = 0;
  for (int k = 1; k < len; ++k) best = v[k] > v[best] ? k : best;
  return best;
}

#ifdef TPR_HAVE_X86_PRICING
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
__attribute__((target("avx512f"))) int ArgMaxAvx512(const double* v,
                                                    int len) {
  __m512d mx = _mm512_loadu_pd(v);
  for (int k = 8; k < len; k += 8) mx = _mm512_max_pd(mx, _mm512_loadu_pd(v + k));
  const __m512d top = _mm512_set1_pd(_mm512_reduce_max_pd(mx));
  for (int k = 0;; k += 8) {
    const __mmask8 hit =
        _mm512_cmp_pd_mask(_mm512_loadu_pd(v + k), top, _CMP_EQ_OQ);
    if (hit != 0) return k + __builtin_ctz(static_cast<unsigned>(hit));
  }
}
#pragma GCC diagnostic pop
#endif

using ArgMaxFn = int (*)(const double*, int);

ArgMaxFn PickArgMax() {
#ifdef TPR_HAVE_X86_PRICING
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f")) return ArgMaxAvx512;
#endif
  return ArgMaxScalar;
}

// Two cheapest entries of a line (Vogel's penalty), with their indices.
struct TwoMin {
  double m1;
  double m2;
  int a1;
  int a2;
};

inline void Offer(double c, int k, TwoMin* t) {
  const bool lt1 = c < t->m1;
  const bool lt2 = c < t->m2;
  t->m2 = lt1 ? t->m1 : (lt2 ? c : t->m2);
  t->a2 = lt1 ? t->a1 : (lt2 ? k : t->a2);
  t->m1 = lt1 ? c : t->m1;
  t->a1 = lt1 ? k : t->a1;
}

// RowTwoMin: over j < cs of row[j] + mask[j] (mask is 0 or +inf, padded).
void RowTwoMinScalar(const double* row, const double* mask, int cs,
                     TwoMin* t) {
  *t = TwoMin{kInf, kInf, -1, -1};
  for (int j = 0; j < cs; ++j) Offer(row[j] + mask[j], j, t);
}

// ColTwoMin: for every column j < cs, over rows i < n of
// cost[i cs + j] + row_mask[i].
void ColTwoMinScalar(const double* cost, int cs, int n,
                     const double* row_mask, TwoMin* out) {
  for (int j = 0; j < cs; ++j) out[j] = TwoMin{kInf, kInf, -1, -1};
  for (int i = 0; i < n; ++i) {
    const double* row = cost + static_cast<size_t>(i) * cs;
    for (int j = 0; j < cs; ++j) Offer(row[j] + row_mask[i], i, &out[j]);
  }
}

#ifdef TPR_HAVE_X86_PRICING
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
// Lane-wise two-minimum: 8 independent (m1, m2) pairs updated with masked
// blends, indices carried as doubles (exact for k < 2^53).
struct Lanes {
  __m512d m1, m2, i1, i2;
};

__attribute__((target("avx512f"))) inline void OfferLanes(__m512d c,
                                                         __m512d idx,
                                                         Lanes* l) {
  const __mmask8 lt1 = _mm512_cmp_pd_mask(c, l->m1, _CMP_LT_OQ);
  const __mmask8 lt2 = _mm512_cmp_pd_mask(c, l->m2, _CMP_LT_OQ);
  l->m2 = _mm512_mask_blend_pd(lt1, _mm512_mask_blend_pd(lt2, l->m2, c), l->m1);
  l->i2 =
      _mm512_mask_blend_pd(lt1, _mm512_mask_blend_pd(lt2, l->i2, idx), l->i1);
  l->m1 = _mm512_mask_blend_pd(lt1, l->m1, c);
  l->i1 = _mm512_mask_blend_pd(lt1, l->i1, idx);
}

__attribute__((target("avx512f"))) void RowTwoMinAvx512(const double* row,
                                                       const double* mask,
                                                       int cs, TwoMin* t) {
  Lanes l{_mm512_set1_pd(kInf), _mm512_set1_pd(kInf), _mm512_set1_pd(-1),
          _mm512_set1_pd(-1)};
  __m512d idx = _mm512_set_pd(7, 6, 5, 4, 3, 2, 1, 0);
  const __m512d step = _mm512_set1_pd(8);
  for (int j0 = 0; j0 < cs; j0 += 8) {
    OfferLanes(
        _mm512_add_pd(_mm512_loadu_pd(row + j0), _mm512_loadu_pd(mask + j0)),
        idx, &l);
    idx = _mm512_add_pd(idx, step);
  }
  alignas(64) double m1[8], m2[8], i1[8], i2[8];
  _mm512_store_pd(m1, l.m1);
  _mm512_store_pd(m2, l.m2);
  _mm512_store_pd(i1, l.i1);
  _mm512_store_pd(i2, l.i2);
  *t = TwoMin{kInf, kInf, -1, -1};
  for (int k = 0; k < 8; ++k) {
    Offer(m1[k], static_cast<int>(i1[k]), t);
    Offer(m2[k], static_cast<int>(i2[k]), t);
  }
}

__attribute__((target("avx512f"))) void ColTwoMinAvx512(
    const double* cost, int cs, int n, const double* row_mask, TwoMin* out) {
  for (int j0 = 0; j0 < cs; j0 += 8) {
    Lanes l{_mm512_set1_pd(kInf), _mm512_set1_pd(kInf), _mm512_set1_pd(-1),
            _mm512_set1_pd(-1)};
    for (int i = 0; i < n; ++i) {
      const __m512d c =
          _mm512_add_pd(_mm512_loadu_pd(cost + static_cast<size_t>(i) * cs + j0),
                        _mm512_set1_pd(row_mask[i]));
      OfferLanes(c, _mm512_set1_pd(i), &l);
    }
    alignas(64) double m1[8], m2[8], i1[8], i2[8];
    _mm512_store_pd(m1, l.m1);
    _mm512_store_pd(m2, l.m2);
    _mm512_store_pd(i1, l.i1);
    _mm512_store_pd(i2, l.i2);
    for (int k = 0; k < 8; ++k) {
      out[j0 + k] = TwoMin{m1[k], m2[k], static_cast<int>(i1[k]),
                           static_cast<int>(i2[k])};
    }
  }
}
#pragma GCC diagnostic pop
#endif

using RowTwoMinFn = void (*)(const double*, const double*, int, TwoMin*);
using ColTwoMinFn = void (*)(const double*, int, int, const double*, TwoMin*);

bool HaveAvx512() {
#ifdef TPR_HAVE_X86_PRICING
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f");
#else
  return false;
#endif
}

RowTwoMinFn PickRowTwoMin() {
#ifdef TPR_HAVE_X86_PRICING
  if (HaveAvx512()) return RowTwoMinAvx512;
#endif
  return RowTwoMinScalar;
}

ColTwoMinFn PickColTwoMin() {
#ifdef TPR_HAVE_X86_PRICING
  if (HaveAvx512()) return ColTwoMinAvx512;
#endif
  return ColTwoMinScalar;
}


}  // namespace

struct EmdSolver::Impl {
  // Problem.
  int n = 0;
  int m = 0;
  int cs = 0;  // cost row stride (multiple of 8)
  std::vector<double> cost;  // n x cs
  std::vector<double> supply;
  std::vector<double> demand;

  // Tree over n + m + 1 nodes; R = n + m.
  std::vector<int> parent;
  std::vector<int> first_child;
  std::vector<int> next_sib;
  std::vector<int> prev_sib;
  std::vector<double> flow;  // flow of the arc joining v and parent[v]
  std::vector<double> pi;    // potentials; u = pi[0..n), v = pi[n..n+m)
  std::vector<int> depth;  // depth[R] = 0

  // Scratch.
  std::vector<double> vpad;
  std::vector<double> rem_a;
  std::vector<double> rem_b;
  std::vector<char> row_open;
  std::vector<char> col_open;
  std::vector<int> row_best;
  std::vector<int> row_second;
  std::vector<int> col_best;
  std::vector<int> col_second;
  std::vector<double> pen;  // rows at [0, np), columns at [np, np + cs)
  std::vector<double> row_mask;
  std::vector<double> col_mask;  // cs entries
  std::vector<TwoMin> two_min;
  std::vector<int> cand_i;  // pricing candidates (one per row at most)
  std::vector<int> cand_j;
  std::vector<int> cell_i;
  std::vector<int> cell_j;
  std::vector<double> cell_f;
  std::vector<int> adj_start;
  std::vector<int> adj_fill;
  std::vector<int> adj;
  std::vector<int> queue;
  std::vector<int> path1;
  std::vector<int> path2;

  EmdStats stats;
  double max_cost = 0.0;  // upper bound of the cost entries

  void Reserve(int nn, int mm, int stride) {
    const size_t nodes = static_cast<size_t>(nn + mm + 1);
    const size_t cells = static_cast<size_t>(nn) * static_cast<size_t>(stride);
    if (cost.size() < cells) cost.resize(cells);
    if (supply.size() < static_cast<size_t>(nn)) supply.resize(nn);
    if (demand.size() < static_cast<size_t>(mm)) demand.resize(mm);
    if (rem_a.size() < static_cast<size_t>(nn)) {
      rem_a.resize(nn);
      cand_i.resize(nn);
      cand_j.resize(nn);
      row_open.resize(nn);
      row_best.resize(nn);
      row_second.resize(nn);
      row_mask.resize(nn);
    }
    if (rem_b.size() < static_cast<size_t>(mm)) {
      rem_b.resize(mm);
      col_open.resize(mm);
      col_best.resize(mm);
      col_second.resize(mm);
    }
    if (vpad.size() < static_cast<size_t>(stride)) {
      vpad.resize(stride);
      col_mask.resize(stride);
      two_min.resize(stride);
    }
    const size_t pen_size = static_cast<size_t>((nn + 7) / 8 * 8 + stride);
    if (pen.size() < pen_size) pen.resize(pen_size);
    if (parent.size() < nodes) {
      parent.resize(nodes);
      first_child.resize(nodes);
      next_sib.resize(nodes);
      prev_sib.resize(nodes);
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
    }
  }

  void Unlink(int v) {
    const int p = parent[v];
    if (prev_sib[v] >= 0) {
      next_sib[prev_sib[v]] = next_sib[v];
    } else {
      first_child[p] = next_sib[v];
    }
    if (next_sib[v] >= 0) prev_sib[next_sib[v]] = prev_sib[v];
  }

  void Link(int v, int p) {
    parent[v] = p;
    prev_sib[v] = -1;
    next_sib[v] = first_child[p];
    if (first_child[p] >= 0) prev_sib[first_child[p]] = v;
    first_child[p] = v;
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

// Initial basis (Vogel's approximation, below). The allocated cells form a
// forest (see the top comment). Masses below kDust left over from rounding (the two
// totals agree only to ~1e-16) are dropped, which changes the cost by less
// than kDust x the largest cost.
void EmdSolver::Impl::InitialBasis() {
  constexpr double kDust = 1e-14;
  const int root = n + m;
  for (int v = 0; v <= root; ++v) {
    first_child[v] = -1;
    next_sib[v] = -1;
    prev_sib[v] = -1;
    parent[v] = -1;
    flow[v] = 0.0;
  }
  for (int i = 0; i < n; ++i) rem_a[i] = supply[i];
  for (int j = 0; j < m; ++j) rem_b[j] = demand[j];
  int cells = 0;
  constexpr int kVogelMinCells = 600;
  // Vogel's approximation: repeatedly take the row or column whose two
  // cheapest open cells differ most (the line that would lose most by not
  // getting its cheapest cell), ship as much as possible along its
  // cheapest cell, and close the exhausted line(s). Its plans are usually
  // within a few percent of optimal, which halves the simplex pivots of a
  // least-cost-per-row start. Each line caches its two cheapest open cells.
  for (int i = 0; i < n; ++i) row_open[i] = rem_a[i] > kDust;
  for (int j = 0; j < m; ++j) col_open[j] = rem_b[j] > kDust;
  const int np = (n + 7) / 8 * 8;
  static const ArgMaxFn argmax = PickArgMax();
  int open_rows = 0;
  int open_cols = 0;
  for (int i = 0; i < n; ++i) open_rows += row_open[i];
  for (int j = 0; j < m; ++j) open_cols += col_open[j];
  // Closed lines are masked by adding +inf to their cells; the two-minimum
  // updates are written as selects so that they compile to conditional
  // moves (the comparisons are unpredictable; branches cost more than the
  // whole scan).
  for (int i = 0; i < n; ++i) row_mask[i] = row_open[i] ? 0.0 : kInf;
  for (int j = 0; j < cs; ++j) col_mask[j] = j < m && col_open[j] ? 0.0 : kInf;
  static const RowTwoMinFn row_two_min = PickRowTwoMin();
  static const ColTwoMinFn col_two_min = PickColTwoMin();
  auto row_scan = [&](int i) {
    TwoMin t;
    row_two_min(&cost[static_cast<size_t>(i) * cs], col_mask.data(), cs, &t);
    row_best[i] = t.a1;
    row_second[i] = t.a2;
    pen[i] = t.m2 - t.m1;  // +inf when one open cell is left: forced
  };
  auto col_scan = [&](int j) {
    double m1 = kInf, m2 = kInf;
    int a1 = -1, a2 = -1;
    for (int i = 0; i < n; ++i) {
      const double c = cost[static_cast<size_t>(i) * cs + j] + row_mask[i];
      const bool lt1 = c < m1;
      const bool lt2 = c < m2;
      m2 = lt1 ? m1 : (lt2 ? c : m2);
      a2 = lt1 ? a1 : (lt2 ? i : a2);
      m1 = lt1 ? c : m1;
      a1 = lt1 ? i : a1;
    }
    col_best[j] = a1;
    col_second[j] = a2;
    pen[np + j] = m2 - m1;
  };
  if (n * m < kVogelMinCells) {
  // Small problems: least cost per row (each row in turn ships its mass to
  // its cheapest open columns). Measured faster overall than Vogel below
  // about 600 cells (at 10 x 10: 3.6 vs 4.8 us; at 30 x 30 a tie; at
  // 60 x 60 Vogel wins by 5%), its extra pivots costing less than
  // Vogel's line choices.
  for (int i = 0; i < n && open_cols > 0; ++i) {
    while (rem_a[i] > kDust && open_cols > 0) {
      TwoMin t;
      row_two_min(&cost[static_cast<size_t>(i) * cs], col_mask.data(), cs, &t);
      const int bj = t.a1;
      const double f = std::min(rem_a[i], rem_b[bj]);
      rem_a[i] -= f;
      rem_b[bj] -= f;
      cell_i[cells] = i;
      cell_j[cells] = bj;
      cell_f[cells] = f;
      ++cells;
      if (rem_b[bj] <= kDust) {
        col_open[bj] = 0;
        col_mask[bj] = kInf;
        --open_cols;
      }
    }
  }
  } else {
  // Closed and padding lines carry penalty -inf, so the choice is a plain
  // argmax over one padded array (vectorized: it runs once per allocation
  // and was the hottest loop of the start when written with branches).
  for (int k = 0; k < np + cs; ++k) pen[k] = -kInf;
  if (open_rows > 0 && open_cols > 0) {
    for (int i = 0; i < n; ++i) {
      if (row_open[i]) row_scan(i);
    }
    col_two_min(cost.data(), cs, n, row_mask.data(), two_min.data());
    for (int j = 0; j < m; ++j) {
      if (!col_open[j]) continue;
      col_best[j] = two_min[j].a1;
      col_second[j] = two_min[j].a2;
      pen[np + j] = two_min[j].m2 - two_min[j].m1;
    }
  }
  while (open_rows > 0 && open_cols > 0) {
    // Lazy refresh: cached penalties may be stale once a cached cell's line
    // has closed; only the line about to be used is rescanned, and only if
    // its cheapest cell has closed (a stale second cell merely skews the
    // penalty), and the choice is made again. (Eager refreshing of every affected line cost
    // more than the pivots it saved.) Any choice yields a valid basis: the
    // start only needs to be good, not exactly Vogel's.
    int bi = -1;
    int bj = -1;
    for (;;) {
      const int k = argmax(pen.data(), np + cs);
      const bool is_row = k < np;
      const int line = is_row ? k : k - np;
      if (is_row) {
        const int a1 = row_best[line];
        if (!col_open[a1]) {
          row_scan(line);
          continue;
        }
        bi = line;
        bj = a1;
      } else {
        const int a1 = col_best[line];
        if (!row_open[a1]) {
          col_scan(line);
          continue;
        }
        bi = a1;
        bj = line;
      }
      break;
    }
    const double f = std::min(rem_a[bi], rem_b[bj]);
    rem_a[bi] -= f;
    rem_b[bj] -= f;
    cell_i[cells] = bi;
    cell_j[cells] = bj;
    cell_f[cells] = f;
    ++cells;
    const bool close_row = rem_a[bi] <= kDust;
    const bool close_col = rem_b[bj] <= kDust;
    if (close_row) {
      row_open[bi] = 0;
      row_mask[bi] = kInf;
      pen[bi] = -kInf;
      --open_rows;
    }
    if (close_col) {
      col_open[bj] = 0;
      col_mask[bj] = kInf;
      pen[np + bj] = -kInf;
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
  pi[root] = 0.0;
  depth[root] = 0;
  for (int s = 0; s < root; ++s) {
    if (parent[s] != -1) continue;
    Link(s, root);
    pi[s] = 0.0;
    depth[s] = 1;
    int head = 0;
    int tail = 0;
    queue[tail++] = s;
    while (head < tail) {
      const int v = queue[head++];
      for (int k = adj_start[v]; k < adj_start[v + 1]; ++k) {
        const int c = adj[k];
        const int w = (v < n) ? n + cell_j[c] : cell_i[c];
        if (parent[w] != -1) continue;  // v's parent (acyclic: no other)
        Link(w, v);
        flow[w] = cell_f[c];
        pi[w] = PotentialFromParent(w);
        depth[w] = depth[v] + 1;
        queue[tail++] = w;
      }
    }
  }
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
  // the last blocking arc in cycle order. Both paths are climbed together
  // by depth, which also finds the apex.
  // The two paths are recorded (path1, path2) so that the flow update and
  // the re-hanging below read arrays instead of chasing parents again.
  double delta1 = kInf;
  int out1 = -1;  // index in path1
  double delta2 = kInf;
  int out2 = -1;  // index in path2
  int len1 = 0;
  int len2 = 0;
  int v1 = first;
  int v2 = second;
  while (v1 != v2) {
    if (depth[v1] >= depth[v2]) {
      if (v1 < n && parent[v1] != root && flow[v1] < delta1) {
        delta1 = flow[v1];
        out1 = len1;
      }
      path1[len1++] = v1;
      v1 = parent[v1];
    } else {
      if ((v2 >= n || parent[v2] == root) && flow[v2] <= delta2) {
        delta2 = flow[v2];
        out2 = len2;
      }
      path2[len2++] = v2;
      v2 = parent[v2];
    }
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
  for (int k = 0; k < len; ++k) Unlink(path[k]);
  for (int k = 0; k < len; ++k) {
    const int v = path[k];
    const double old = flow[v];
    Link(v, k == 0 ? t : path[k - 1]);
    flow[v] = carried;
    carried = old;
  }
  // Every potential in the moved subtree shifts by the same amount, the
  // one that zeroes the entering arc's reduced cost rc = c + pi_i - pi_j:
  // -rc if the supply end moved, +rc if the demand end did. Depths are
  // recomputed top-down (they do not shift uniformly: the path reversed).
  const double shift = out_on_first ? -rc : rc;
  int top = 0;
  queue[top++] = s;
  while (top > 0) {
    const int v = queue[--top];
    pi[v] += shift;
    depth[v] = depth[parent[v]] + 1;
    for (int c = first_child[v]; c >= 0; c = next_sib[c]) queue[top++] = c;
  }
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
  static const CollectFn collect = PickCollect();
  int candidates = 0;
  while (stats.pivots < max_pivots) {
    // Minor pass over the candidates.
    double best = -tol;
    int pick = -1;
    for (int c = 0; c < candidates; ++c) {
      const int i = cand_i[c];
      const int j = cand_j[c];
      const double rc = (cost[static_cast<size_t>(i) * cs + j] + pi[i]) - pi[n + j];
      if (rc < best) {
        best = rc;
        pick = c;
      }
    }
    if (pick < 0) {
      // Major pass.
      for (int j = 0; j < m; ++j) vpad[j] = pi[n + j];
      candidates =
          collect(cost.data(), cs, n, pi.data(), vpad.data(), tol,
                  cand_i.data(), cand_j.data());
      if (candidates == 0) break;  // optimal
      continue;
    }
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

double EmdSolver::Distance(const PreparedSignature& a,
                           const PreparedSignature& b) {
  assert(a.size() >= 1 && a.size() <= kMaxFeatures);
  assert(b.size() >= 1 && b.size() <= kMaxFeatures);
  if (impl_ == nullptr) impl_ = new Impl;
  Impl& s = *impl_;
  s.n = a.size();
  s.m = b.size();
  s.cs = b.stride();
  s.Reserve(s.n, s.m, s.cs);
  s.max_cost = GroundDistanceMatrix(a, b, s.cost.data(), s.cs);
  for (int i = 0; i < s.n; ++i) s.supply[i] = a.weight(i);
  for (int j = 0; j < s.m; ++j) s.demand[j] = b.weight(j);
  return s.Solve();
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

double Emd(const PreparedSignature& a, const PreparedSignature& b) {
  thread_local EmdSolver solver;
  return solver.Distance(a, b);
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
double EmdLowerBound(const PreparedSignature& a, const PreparedSignature& b) {
  const double* ca = a.centroid();
  const double* cb = b.centroid();
  const int ba = a.bands();
  const int bb = b.bands();
  const int common = std::min(ba, bb);
  double result = std::abs(ca[0] - cb[0]);
  for (int block = 0; block < 3; ++block) {
    const double* x = ca + 1 + block * ba;
    const double* y = cb + 1 + block * bb;
    double s = 0.0;
    for (int d = 0; d < common; ++d) s += (x[d] - y[d]) * (x[d] - y[d]);
    for (int d = common; d < ba; ++d) s += x[d] * x[d];
    for (int d = common; d < bb; ++d) s += y[d] * y[d];
    result += std::sqrt(s);
  }
  return result;
}

}  // namespace tpr::index
