// Mesh decimation: fewer vertices, same shape, same topology. One free
// function; OpenMesh and its decimater stay in decimation.cc.
//
//   absl::StatusOr<Mesh> small = SimplifyMesh(mesh, /*target_vertices=*/3000);
//   if (small.ok()) Use(*small);  // at most ~3000 vertices, closed if mesh was
#ifndef TPR_EXTRACTOR_LIB_DECIMATION_H_
#define TPR_EXTRACTOR_LIB_DECIMATION_H_

#include "absl/status/statusor.h"
#include "extractor/lib/mesh.h"

namespace tpr::extract {

// SimplifyMesh returns `mesh` decimated with OpenMesh's DecimaterT and its
// quadric error module (Garland-Heckbert edge collapses) until at most
// target_vertices vertices remain, unreferenced vertices removed (ids in order
// of first reference). A roundness constraint refuses collapses that would
// create a triangle with an angle under 20 degrees (slivers spoil the FEM
// eigenvalues, see spectrum.cc), so the decimater may stop above the target. A
// mesh already at or below the target is returned compacted but otherwise
// unchanged. Topology is preserved. Errors: INVALID_ARGUMENT for
// target_vertices < 4 or a triangle OpenMesh refuses (a non-manifold
// configuration; the message names the triangle). Cost O(V log V).
// Thread-safe (no shared state).
absl::StatusOr<Mesh> SimplifyMesh(const Mesh& mesh, int target_vertices);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_DECIMATION_H_
