// TPR extraction (Tam & Lau 2007, sections 4 and 5): mesh -> signature.
//
//   Options options;                          // the paper's defaults
//   absl::StatusOr<ExtractResult> r = ExtractSignature(loaded.mesh, options);
//   if (r.ok()) Store(r->signature);
#ifndef TPR_EXTRACTOR_LIB_EXTRACT_H_
#define TPR_EXTRACTOR_LIB_EXTRACT_H_

#include "absl/status/statusor.h"
#include "extractor/lib/mesh.h"
#include "extractor/lib/signature.h"

namespace tpr::extract {

// Options carries every parameter of the pipeline. Defaults are the paper's
// values where it gives one; otherwise the comment says how it was chosen.
struct Options {
  // Geodesic bands per feature for the surface vectors (5.3, Fig. 8).
  // Default 20.
  int bands = 20;
  // Critical Point Analysis: a cycle is valid when it has more than this
  // many vertices (4.3, "we choose n = 1"). Default 1.
  int cycle_min_vertices = 1;
  // Topological Ring Extraction: a merge is a ring when its region length
  // (Eq. 3) exceeds this fraction of MAX g_o. Default 0.05.
  double ring_length_threshold = 0.05;
  // Threads for independent Dijkstra sweeps; <= 1 runs on the caller's
  // thread. The result does not depend on it. Default 1.
  int threads = 1;
  // Fill ExtractResult::explanation. Default false.
  bool explain = false;
};

// ExtractSignature runs the whole TPR pipeline on a mesh that intake
// validated. Errors: INVALID_ARGUMENT for options out of range or a mesh the
// method cannot describe (the message says why). Thread-safe (no shared
// state). Cost: about (7 + R + psi + mu + gamma) Dijkstra sweeps (Table 4).
absl::StatusOr<ExtractResult> ExtractSignature(const Mesh& mesh,
                                               const MeshStats& stats,
                                               const Options& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_EXTRACT_H_
