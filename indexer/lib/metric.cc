#include "indexer/lib/metric.h"

namespace tpr::index {

namespace {

// The spectral and heat-trace part of d_w, added to `sum` in that order.
double AddEmbeddings(double sum, const PreparedSignature& a,
                     const PreparedSignature& b, const TermWeights& w) {
  if (w.spectral > 0.0) sum += w.spectral * SpectralDistance(a, b);
  if (w.heat > 0.0) sum += w.heat * HeatDistance(a, b);
  return sum;
}

}  // namespace

double Distance(EmdSolver& solver, const PreparedSignature& a,
                const PreparedSignature& b, const TermWeights& w) {
  return AddEmbeddings(w.emd > 0.0 ? w.emd * solver.Distance(a, b) : 0.0, a, b,
                       w);
}

double Distance(const PreparedSignature& a, const PreparedSignature& b,
                const TermWeights& w) {
  return AddEmbeddings(w.emd > 0.0 ? w.emd * Emd(a, b) : 0.0, a, b, w);
}

double DistanceLowerBound(const PreparedSignature& a,
                          const PreparedSignature& b, const TermWeights& w) {
  return AddEmbeddings(w.emd > 0.0 ? w.emd * EmdLowerBound(a, b) : 0.0, a, b,
                       w);
}

}  // namespace tpr::index
