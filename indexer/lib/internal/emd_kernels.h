// The EMD's vectorized kernels (library-internal): the pricing pass of the
// network simplex and the three kernels of its start, in a scalar version
// (the oracle) and AVX2 and AVX-512F twins that return the same values bit
// for bit (simd.h). emd.cc calls them through EmdKernelsFor(
// ChosenSimdLevel()), one table chosen once.
//
// Files: emd_kernels_scalar.cc (and the table lookup),
// emd_kernels_avx2.cc (-mavx2 -mfma), emd_kernels_avx512.cc (-mavx512f).
// The wide files define everything in an anonymous namespace and include
// no header with inline functions of their own (only immintrin.h and
// this one), so that no wide instruction leaks into a function the linker
// could pick for baseline code.
#ifndef TPR_INDEXER_LIB_INTERNAL_EMD_KERNELS_H_
#define TPR_INDEXER_LIB_INTERNAL_EMD_KERNELS_H_

#include <cstdint>

#include "indexer/lib/internal/simd.h"

namespace tpr::index::internal {

// CollectFn: the major pricing pass. It scans the n x cs reduced costs
// (cost[i cs + j] + u[i]) - v[j] of the row-major matrix `cost` (cs a
// positive multiple of 8) and, for every column j with one below -tol,
// appends (i, j) with i its most negative row (the first on ties) to
// cand_i / cand_j (cs entries each), columns in increasing order; returns
// the count. v holds cs entries (padding columns -inf, so they never
// qualify).
using CollectFn = int (*)(const double* cost, int cs, int n, const double* u,
                          const double* v, double tol, int* cand_i,
                          int* cand_j);

// RowArgMinFn returns the first j < cs minimizing row[j] + offset[j] among
// the columns whose bit in the closed set is clear: bit j of closed_lo for
// j < 64, bit j % 64 of closed[j / 64] above (closed[0] is not read).
// Preconditions: cs a positive multiple of 8, at least one column open,
// every open row[j] + offset[j] finite. Why a bit set, and the first 64
// columns' part passed in a register: the start closes a column after
// about half of its allocations, by a store whose address comes from the
// search just done, and the next search reads the closed set at once.
// With the set in memory (as +inf offsets, or as bits) a whole EMD at
// n = m = 30 took about 5% longer than with the word in a register (side
// by side, same values).
using RowArgMinFn = int (*)(const double* row, const double* offset,
                            uint64_t closed_lo, const uint64_t* closed, int cs);

// ColumnMinFn writes out[j] = min over i < n of cost[i cs + j] for j < cs
// (cs a positive multiple of 8, n >= 1).
using ColumnMinFn = void (*)(const double* cost, int cs, int n, double* out);

// RankOrderFn writes order[r_i] = i for i < n, where r_i counts the k < n
// with w[k] < w[i], or w[k] == w[i] and k < i: the indices in increasing
// order of w, ties by index (a stable sort). Precondition: 1 <= n <= 256
// (the EMD's n <= kMaxFeatures).
using RankOrderFn = void (*)(const double* w, int n, int* order);

// EmdKernels: one variant of every EMD kernel.
struct EmdKernels {
  CollectFn collect;
  RowArgMinFn row_arg_min;
  ColumnMinFn column_min;
  RankOrderFn rank_order;
};

// EmdKernelsFor returns the kernels of `level`, or nullptr when
// !SimdLevelSupported(level) (never for kScalar). O(1) after the first
// CPU query; thread-safe.
const EmdKernels* EmdKernelsFor(SimdLevel level);

// The tables of the wide files, for EmdKernelsFor only: calling one
// runs code of that instruction set, so only after SimdLevelSupported.
const EmdKernels* EmdKernelsAvx2Table();
const EmdKernels* EmdKernelsAvx512Table();

}  // namespace tpr::index::internal

#endif  // TPR_INDEXER_LIB_INTERNAL_EMD_KERNELS_H_
