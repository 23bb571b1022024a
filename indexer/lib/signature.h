// The indexer's view of a TPR signature: a weighted set of features, each a
// point in the ground-distance space of Eq. 7 (Tam & Lau 2007, section 6).
// The indexer library does not know the extractor; services convert from
// tpr.v1.Signature.
//
//   Signature s;
//   s.features.push_back({/*weight=*/1.0, /*g=*/0.4, k, a, h});
//   if (absl::Status st = ValidateSignature(s); !st.ok()) return st;
#ifndef TPR_INDEXER_LIB_SIGNATURE_H_
#define TPR_INDEXER_LIB_SIGNATURE_H_

#include <vector>

namespace tpr::index {

// Feature: EMD mass and the coordinates Eq. 7 compares.
struct Feature {
  // Normalized effective area (Eq. 6), >= 0.
  double weight = 0.0;
  // Normalized integral geodesic G'_norm (Eq. 5), in [0, 1].
  double g = 0.0;
  // Band vectors (5.3): curvature K, area A, average distance H; equal
  // lengths within a signature.
  std::vector<double> k;
  std::vector<double> a;
  std::vector<double> h;
};

// Signature: the features of one model; weights sum to 1.
struct Signature {
  std::vector<Feature> features;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_SIGNATURE_H_
