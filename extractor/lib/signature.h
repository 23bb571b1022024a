// What extraction produces: the TPR signature of one mesh (Tam & Lau 2007,
// sections 4 and 5) plus timings, warnings and an optional explanation.
// The wire form is tpr.v1.Signature; the services convert.
//
//   absl::StatusOr<ExtractResult> r = ExtractSignature(mesh, Options{});
//   for (const Feature& f : r->signature.features) Use(f.weight, f.curvature);
#ifndef TPR_EXTRACTOR_LIB_SIGNATURE_H_
#define TPR_EXTRACTOR_LIB_SIGNATURE_H_

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "extractor/lib/mesh.h"

namespace tpr::extract {

// FeatureKind: a topological point (protrusion tip, 4.3-4.4) or a
// topological ring (joint, 4.6).
enum class FeatureKind { kPoint, kRing };

// Feature is one topological feature and its geometric description (5).
// Every quantity is dimensionless and invariant to rotation, translation and
// uniform scale.
struct Feature {
  FeatureKind kind = FeatureKind::kPoint;
  // Effective area / total area (Eq. 6); a signature's weights sum to 1.
  double weight = 0.0;
  // Normalized integral geodesic G'_norm in [0, 1] (Eqs. 4, 5).
  double integral_geodesic = 0.0;
  // Geometric surface vectors (5.3), one entry per geodesic band:
  // segment-area-weighted mean of the band's segments' integrated Gaussian
  // curvature (sum of angle defects in radians; a genus-0 mesh's bands of
  // one segment each sum to 4 pi),
  std::vector<double> curvature;
  // segment-area-weighted mean of the band's segment areas / total area
  // (5.3: each band's value is the area-weighted average over its
  // segments; a band of one segment gives band area / total area),
  std::vector<double> area;
  // area-weighted segment thickness / sqrt(total area).
  std::vector<double> distance;
};

// Signature is the description of one mesh that the indexer stores.
struct Signature {
  // Points first, then rings.
  std::vector<Feature> features;
  MeshStats stats;
  // The Laplace-Beltrami spectrum: the first non-zero eigenvalues, ascending,
  // each lambda_i * A / (4 pi) (A = total surface area), so the unit sphere
  // gives l (l + 1). tpr.v1.Signature.spectrum documents it. Computed by
  // LaplaceBeltramiSpectrum (spectrum.h); N = Options::spectrum_eigenvalues,
  // empty when 0.
  std::vector<double> spectrum;
};

// Explanation locates the features on the mesh, for drawing.
struct Explanation {
  // Per vertex: the TPR region id (PR, SR or FR; see 5.2), -1 if none.
  std::vector<int32_t> vertex_region;
  // Per feature (parallel to Signature::features): its vertices; one for a
  // point, the wavefront's vertices for a ring.
  std::vector<std::vector<int32_t>> feature_vertices;
};

// StageTiming is the wall-clock time of one pipeline stage.
struct StageTiming {
  std::string stage;
  double milliseconds = 0.0;
};

// ExtractResult is everything one extraction returns.
struct ExtractResult {
  Signature signature;
  std::vector<StageTiming> timings;
  // One sentence per condition the paper handles poorly (genus > 0,
  // boundaries, several components).
  std::vector<std::string> warnings;
  // Set when Options::explain.
  std::optional<Explanation> explanation;
};

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_SIGNATURE_H_
