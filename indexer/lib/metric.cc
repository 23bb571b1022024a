#include "indexer/lib/metric.h"

namespace tpr::index {

double Distance(EmdSolver& solver, const PreparedSignature& a,
                const PreparedSignature& b) {
  return solver.Distance(a, b) + SpectralDistance(a, b);
}

double Distance(const PreparedSignature& a, const PreparedSignature& b) {
  return Emd(a, b) + SpectralDistance(a, b);
}

double DistanceLowerBound(const PreparedSignature& a,
                          const PreparedSignature& b) {
  return EmdLowerBound(a, b) + SpectralDistance(a, b);
}

}  // namespace tpr::index
