// Scalar EMD kernels (emd_kernels.h): the oracle of the wide twins, and
// the variant of CPUs without AVX2. Also the one table lookup.
#include <algorithm>
#include <cstddef>
#include <limits>

#include "indexer/lib/internal/emd_kernels.h"

namespace tpr::index::internal {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Per column rather than per row (emd.cc explains the pricing scheme):
// lanes run over 8 consecutive columns of the row-major matrix, and each
// lane keeps its own minimum and row, so the pass has no horizontal
// reduction and no data-dependent branch; the wide twins keep that shape.
int CollectScalar(const double* cost, int cs, int n, const double* u,
                  const double* v, double tol, int* cand_i, int* cand_j) {
  int count = 0;
  for (int j0 = 0; j0 < cs; j0 += 8) {
    double mn[8];
    int arg[8];
    for (int l = 0; l < 8; ++l) {
      mn[l] = -tol;
      arg[l] = -1;
    }
    for (int i = 0; i < n; ++i) {
      const double* row = cost + static_cast<size_t>(i) * cs + j0;
      const double ui = u[i];
      for (int l = 0; l < 8; ++l) {
        const double r = (row[l] + ui) - v[j0 + l];
        const bool lt = r < mn[l];
        mn[l] = lt ? r : mn[l];
        arg[l] = lt ? i : arg[l];
      }
    }
    for (int l = 0; l < 8; ++l) {
      cand_i[count] = arg[l];
      cand_j[count] = j0 + l;
      count += arg[l] >= 0;
    }
  }
  return count;
}

inline uint64_t ClosedWord(uint64_t closed_lo, const uint64_t* closed, int j) {
  return j < 64 ? closed_lo : closed[j >> 6];
}

int RowArgMinScalar(const double* row, const double* offset, uint64_t closed_lo,
                    const uint64_t* closed, int cs) {
  int best = -1;
  double bv = kInf;
  for (int j = 0; j < cs; ++j) {
    const bool shut = (ClosedWord(closed_lo, closed, j) >> (j & 63)) & 1u;
    const double c = shut ? kInf : row[j] + offset[j];
    const bool take = best < 0 ? !shut : c < bv;
    best = take ? j : best;
    bv = take ? c : bv;
  }
  return best;
}

// Exact in any order (a minimum rounds nothing), so every variant gives
// the same values.
void ColumnMinScalar(const double* cost, int cs, int n, double* out) {
  for (int j = 0; j < cs; ++j) out[j] = cost[j];
  for (int i = 1; i < n; ++i) {
    const double* row = cost + static_cast<size_t>(i) * cs;
    for (int j = 0; j < cs; ++j) out[j] = std::min(out[j], row[j]);
  }
}

// O(n^2) comparisons, but branch-free and vectorizable, which beats a
// comparison sort's unpredictable branches at these sizes.
void RankOrderScalar(const double* w, int n, int* order) {
  for (int i = 0; i < n; ++i) {
    const double wi = w[i];
    int rank = 0;
    for (int k = 0; k < n; ++k) {
      const double wk = w[k];
      rank += (wk < wi) | ((wk == wi) & (k < i));
    }
    order[rank] = i;
  }
}

constexpr EmdKernels kScalarKernels = {CollectScalar, RowArgMinScalar,
                                       ColumnMinScalar, RankOrderScalar};

}  // namespace

const EmdKernels* EmdKernelsFor(SimdLevel level) {
  if (!SimdLevelSupported(level)) return nullptr;
  switch (level) {
#ifdef TPR_HAVE_X86_KERNELS
    case SimdLevel::kAvx2:
      return EmdKernelsAvx2Table();
    case SimdLevel::kAvx512:
      return EmdKernelsAvx512Table();
#endif
    case SimdLevel::kScalar:
      return &kScalarKernels;
    default:
      return nullptr;
  }
}

}  // namespace tpr::index::internal
