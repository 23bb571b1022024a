// The indexer's view of a TPR signature: a weighted set of features, each a
// point in the ground-distance space of Eq. 7 (Tam & Lau 2007, section 6),
// plus the mesh's Laplace-Beltrami spectrum.
// The indexer library does not know the extractor; services convert from
// tpr.v1.Signature.
//
//   Signature s;
//   s.features.push_back({/*weight=*/1.0, /*integral_geodesic=*/0.4,
//                         curvature, area, distance});
//   if (absl::Status st = ValidateSignature(s); !st.ok()) return st;
#ifndef TPR_INDEXER_LIB_SIGNATURE_H_
#define TPR_INDEXER_LIB_SIGNATURE_H_

#include <array>
#include <vector>

namespace tpr::index {

// Feature: EMD mass and the coordinates Eq. 7 compares.
struct Feature {
  // Normalized effective area (Eq. 6), >= 0.
  double weight = 0.0;
  // Normalized integral geodesic G'_norm (Eq. 5), in [0, 1].
  double integral_geodesic = 0.0;
  // Band vectors (5.3), one entry per geodesic band, equal lengths within a
  // signature (tpr.v1.Feature documents their meaning): curvature K,
  std::vector<double> curvature;
  // area A (band area / total area, >= 0),
  std::vector<double> area;
  // and average distance H ("thickness" / sqrt(total area)).
  std::vector<double> distance;
};

// BandVectors lists a feature's band vectors in wire order (curvature, area,
// distance). Code that treats them alike (validation, serialization) loops
// over this list, so a new band vector is added here once.
inline std::array<const std::vector<double>*, 3> BandVectors(const Feature& f) {
  return {&f.curvature, &f.area, &f.distance};
}
inline std::array<std::vector<double>*, 3> BandVectors(Feature& f) {
  return {&f.curvature, &f.area, &f.distance};
}

// Signature: the features of one model (weights sum to 1) and its
// Laplace-Beltrami spectrum.
struct Signature {
  std::vector<Feature> features;
  // The first non-zero eigenvalues lambda_i A / (4 pi), ascending, each
  // finite and > 0 (tpr.v1.Signature.spectrum documents it); compared by
  // the spectral term of the distance (spectral.h, metric.h). May be empty
  // (the term then sees its Weyl padding, spectral.h).
  std::vector<double> spectrum;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_SIGNATURE_H_
