// The questions a search answers, each as one fixed weighting of the
// distance's terms:
//
//   d_w(A, B) = w.emd * EMD(A, B) + w.spectral * S(A, B) + w.heat * H(A, B),
//
// EMD the paper's distance (section 6.1, ground distance of Eq. 7), S the
// spectral term (spectral.h, SpectralEmbedding at weight 1) and H the
// heat-trace term (spectral.h, HeatTraceEmbedding).
//
// Why every d_w with non-negative weights is a metric (so one VP-tree
// answers every intent exactly). EMD is a pseudometric (metric.h, 1.); S
// and H are Euclidean distances between images of fixed maps, hence
// pseudometrics. For w >= 0 each scaled term w_t * T is a pseudometric
// (non-negativity, symmetry and T(A, A) = 0 survive a factor >= 0, and the
// triangle inequality is multiplied through by w_t >= 0); the sum of
// pseudometrics is one, term by term:
//   d_w(A, C) = sum_t w_t T(A, C) <= sum_t w_t [T(A, B) + T(B, C)]
//             = d_w(A, B) + d_w(B, C).
// Lower bounds add the same way: with L_t <= T for each term,
// sum_t w_t L_t <= d_w, which is what the tree's per-term bounds use.
//
//   TermWeights w = IntentWeights(Intent::kIdentity);
//   double d = w.emd * emd + w.spectral * s + w.heat * h;
#ifndef TPR_INDEXER_LIB_INTENT_H_
#define TPR_INDEXER_LIB_INTENT_H_

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace tpr::index {

// TermWeights: the factor of each term of d_w above, dimensionless. Valid
// when every factor is finite and >= 0 and at least one is > 0.
struct TermWeights {
  double emd = 1.0;
  double spectral = 0.0;
  double heat = 0.0;
};

// Intent: which question a search answers (proto tpr.v1.Intent).
enum class Intent {
  // A compromise between the two below; the index's own distance (its
  // VP-tree is built with it) and the default of every search.
  kBalanced,
  // The same model, character or person in any pose.
  kIdentity,
  // Other models of the same kind.
  kKind,
};

// IntentWeights returns the fixed weighting of `intent`. O(1); thread-safe.
TermWeights IntentWeights(Intent intent);

// IntentName returns "balanced", "identity" or "kind".
const char* IntentName(Intent intent);
// ParseIntent is its inverse; INVALID_ARGUMENT for another name.
absl::StatusOr<Intent> ParseIntent(absl::string_view name);

// ValidateTermWeights returns OK when `w` is valid (see TermWeights),
// INVALID_ARGUMENT naming the first bad factor otherwise. O(1).
absl::Status ValidateTermWeights(const TermWeights& w);

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_INTENT_H_
