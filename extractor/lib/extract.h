// TPR extraction (Tam & Lau 2007, sections 4 and 5): mesh -> signature,
// plus the Laplace-Beltrami spectrum (spectrum.h).
//
//   Options options;                          // the paper's defaults
//   absl::StatusOr<ExtractResult> r =
//       ExtractSignature(mesh, ComputeMeshStats(mesh), options);
//   if (r.ok()) Store(r->signature);
#ifndef TPR_EXTRACTOR_LIB_EXTRACT_H_
#define TPR_EXTRACTOR_LIB_EXTRACT_H_

#include "absl/status/statusor.h"
#include "extractor/lib/geodesic.h"
#include "extractor/lib/integral_geodesic.h"
#include "extractor/lib/mesh.h"
#include "extractor/lib/signature.h"
#include "extractor/lib/spectrum.h"

namespace tpr::extract {

// TopologyMethod is how the critical points of each source's field are
// cleaned of the extraneous ones before the vote of 4.4.
enum class TopologyMethod {
  // Persistence simplification (not in the paper): of each source's
  // geodesic field, keep the maxima whose 0-dimensional persistence is at
  // least Options::point_min_prominence x sqrt(area), and as saddles only
  // the vertices where those maxima's superlevel components die
  // (topological_points.h, SimplifyByPersistence). The vote of 4.4 then runs
  // on these, so a point's search radius reaches the branching of its whole
  // protrusion: the fingers of a hand or the toes and heel of a foot are
  // one point, not one per finger that happened to win the vote in this
  // pose, and a bump shorter than the threshold is no point at all.
  kPersistence,
  // The paper (4.3-4.4): Critical Point Analysis's cycle-size filter
  // (Options::cycle_min_vertices) and every saddle it registers. Its counts
  // follow the mesh's small protrusions and resolution: on the SCAPE person
  // 6 to 16 points over 71 poses.
  kPaper,
};

// Options carries every parameter of the pipeline. Defaults are the paper's
// values where it gives one; otherwise the comment says how it was chosen.
struct Options {
  // Geodesic bands per feature for the surface vectors (5.3, Fig. 8).
  // In common::kMinBands..kMaxBands (1..256). Default 20.
  int bands = 20;
  // Geodesic bands span [0, the largest geodesic distance from the feature]
  // when true (each feature's own extent); when false they span [0, the
  // mesh's geodesic diameter, the distance between the two far source
  // points of 4.5], the same absolute range for every feature of a mesh
  // (5.3 and Fig. 8 do not say which). Default true.
  bool bands_per_feature_extent = true;
  // Critical Point Analysis: a cycle is valid when it has more than this
  // many vertices (4.3, "we choose n = 1"). Default 1.
  int cycle_min_vertices = 1;
  // Critical Point Analysis: how many edges from a saddle candidate the
  // search of C(l_s)^+ goes (the paper's "around v", see
  // CriticalPointOptions::search_hops). Must exceed cycle_min_vertices.
  // Default 6.
  int cycle_search_hops = 6;
  // How Critical Point Analysis's maxima and saddles are filtered before
  // Topological Point Selection (4.3-4.4); see TopologyMethod. Default
  // kPersistence.
  TopologyMethod topology = TopologyMethod::kPersistence;
  // TopologyMethod::kPersistence: the shortest protrusion that holds a
  // topological point, as the persistence of its maximum in a source's
  // geodesic distance field (about the protrusion's length less the half
  // girth of its base) / sqrt(total area), so that it does not depend on
  // scale or resolution. In [0, 1]; ignored by kPaper. Default 0.05: on the
  // SCAPE person (docs/tpr-stability.md) the head, the shortest limb, stands
  // at 0.13 to 0.25 in every pose, while toes, heels, fingers, bent elbows
  // and knees stay below 0.05 in nearly all. Smaller values keep more of a
  // model's small protrusions (an armadillo's claws), which helps tell kinds
  // apart and costs pose stability (figures in docs/tpr-stability.md).
  double point_min_prominence = 0.05;
  // Topological Ring Extraction under TopologyMethod::kPaper: a front's
  // wavefront is a ring when its region length (Eq. 3) exceeds this
  // fraction of MAX g_o (the paper gives no number, 4.6.2). Chosen by
  // measurement on the synthetic classes (see
  // tests/extractor/extract_test.cc): 0.05 keeps the joints of bipeds and
  // quadrupeds and drops the slivers of near-simultaneous merges. Ignored
  // by kPersistence (ring_min_length). In [0, 1) (common::RingLengthInRange).
  // Default 0.05.
  double ring_length_threshold = 0.05;
  // Topological Ring Extraction under TopologyMethod::kPersistence: the
  // same test with the threshold as this fraction of sqrt(total area)
  // instead. MAX g_o is measured from the surface centre, which the
  // hierarchical search of 4.5 places on a flat minimum of G (a torso's
  // front or back), so it moved by a tenth between a generated biped and a
  // rotated, scaled copy of it, and every ring length near the threshold
  // flips with it; the area does not move. In [0, 1)
  // (common::RingLengthInRange). Default 0.04: on the
  // SCAPE person MAX g_o is 0.8 to 0.9 sqrt(area), so this is the paper
  // threshold's 0.05 of MAX g_o in the area's unit (docs/tpr-stability.md).
  double ring_min_length = 0.04;
  // Topological Ring Extraction: also stop once every saddle of the
  // centre-sourced analysis is visited (4.6.3's shortcut); see
  // RingOptions::stop_at_centre_saddles for why it is off. Default false.
  bool ring_stop_at_centre_saddles = false;
  // Cut every handle before describing (mesh_handles.h): while the mesh
  // (closed, genus > 0) has a non-separating cycle, cut the shortest open
  // and cap both sides, so that the TPR stages and the spectrum see a
  // genus-0 surface, which is what the paper's analysis assumes (7.4).
  // A handle fused from a contact (a tail grown into a foot) then no
  // longer moves every geodesic and eigenvalue; a real handle (a cup's)
  // becomes a hook, the same way on every mesh. Not in the paper; false
  // describes the mesh as it is (the paper's method). A mesh with a
  // boundary is described as it is. Default true: chosen by
  // cross-validation over every dev set (docs/results.md).
  bool cut_handles = true;
  // Surface-centre search (4.5) and MAX G estimate, see
  // integral_geodesic.h. Defaults there.
  IntegralGeodesicOptions integral_geodesic;
  // How the mesh graph approximates geodesics, see geodesic.h.
  GeodesicOptions geodesic;
  // Laplace-Beltrami eigenvalues stored in Signature::spectrum (not part
  // of the paper; the spectral and heat-trace terms of the distance,
  // indexer/lib/spectral.h); 0 skips the stage. In [0, 1000]. Default 50:
  // the count ShapeDNA's reference scores use and the most the searched
  // terms compare by default (index::SpectralOptions::eigenvalues,
  // HeatTraceOptions::eigenvalues, chosen by cross-validation,
  // docs/results.md); a search comparing more pads a shorter spectrum with
  // its Weyl asymptote. Cost: see SpectrumOptions::eigenvalues.
  int spectrum_eigenvalues = 50;
  // The rest of the spectrum's parameters (simplification bound, solver;
  // the count is spectrum_eigenvalues). Defaults there.
  SpectrumSolverOptions spectrum;
  // Threads for independent Dijkstra sweeps; <= 1 runs on the caller's
  // thread. With more than 1 the spectrum also runs on a thread of its
  // own beside the TPR stages. The result does not depend on it.
  // Default 1.
  int threads = 1;
  // Fill ExtractResult::explanation. Default false.
  bool explain = false;
};

// ExtractSignature runs the whole TPR pipeline on a mesh that intake
// validated: source points (4.5), Critical Point Analysis from each (4.3),
// Topological Point Selection (4.4), Topological Ring Extraction (4.6) and
// the geometric features of every point and ring (5). Only the largest
// connected component (by area) is described; quantities are normalized by
// its area. Meshes the paper handles poorly (genus > 0, boundaries, several
// components) still get a signature, with a sentence in `warnings`; with
// Options::cut_handles a closed mesh of genus > 0 is first cut to genus 0
// (mesh_handles.h; a warning names the cuts) and described so, and the
// explanation's vertex ids are the input's. A mesh
// on which no topological point is found (a sphere-like blob) gets one
// point feature at the surface centre with weight 1 and a warning. A
// topological point whose ring-extraction wavefront never starts (another
// front sweeps it before its Eq. 1 start time) is dropped: it bounds no
// region and would carry no effective area (see extract.cc).
// Timings: stages "graph", "source_points", "critical_points",
// "topological_points", "point_features", "topological_rings",
// "ring_features", "signature", "spectrum", in that order ("spectrum" only
// when Options::spectrum_eigenvalues > 0). The spectrum describes the whole
// mesh (every component), unlike the TPR features. Explanation region ids: 0 is
// FR, then one per ring (TopologicalRings' regions).
// Errors: INVALID_ARGUMENT for options out of range, or a mesh with no
// vertex, out-of-range indices, non-finite coordinates, zero area, or too
// few vertices for spectrum_eigenvalues (the message says which);
// INTERNAL when the spectrum's eigensolver does not converge. Thread-safe (no
// shared state). Cost: about (7 + R + psi + mu + gamma) Dijkstra sweeps (Table
// 4); with threads > 1 the independent sweeps (the three analyses, the
// per-feature geodesics) run in parallel, with identical results. The spectrum
// adds one simplification and one sparse eigensolve (see
// LaplaceBeltramiSpectrum), on the caller's thread after the TPR stages, or
// with threads > 1 on a thread of its own during them.
absl::StatusOr<ExtractResult> ExtractSignature(const Mesh& mesh,
                                               const MeshStats& stats,
                                               const Options& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_EXTRACT_H_
