// Debris: connected components of a mesh so small against its largest
// component that they are export leftovers (helper geometry, stray
// triangles, specks) rather than parts of the shape. Intake drops them
// (CleanPolygonSoup, mesh_clean.h) so that they change neither which
// component is described, nor whether handles are cut, nor the spectrum.
//
// The rule: a component is debris when its area is below
// DebrisOptions::area_fraction of the largest component's (the one of
// largest area) AND its vertex count is below
// DebrisOptions::vertex_fraction of that component's. Both must hold: a
// small but finely meshed part (a figure's eye) or a large coarse one (a
// table's flat top) is kept.
//
//   DebrisDropped d = DropDebris(mesh.positions, &triangles);
//   if (d.components > 0) warnings.push_back(DebrisWarning(d));
#ifndef TPR_EXTRACTOR_LIB_DEBRIS_H_
#define TPR_EXTRACTOR_LIB_DEBRIS_H_

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tpr::extract {

// DebrisOptions: the thresholds of the rule above.
struct DebrisOptions {
  // Largest area of a debris component, as a fraction of the largest
  // component's area. Default 0.01.
  double area_fraction = 0.01;
  // Largest vertex count of a debris component, as a fraction of the
  // largest component's vertex count. Default 0.01.
  double vertex_fraction = 0.01;
};

// DebrisDropped: what DropDebris removed.
struct DebrisDropped {
  int64_t components = 0;
  int64_t triangles = 0;
  // Vertices only the dropped triangles referenced (left unreferenced in
  // the positions; CompactVertices removes them).
  int64_t vertices = 0;
};

// DropDebris removes from `triangles` every triangle of a debris component
// (components: triangles joined through shared vertex ids), keeping the
// order of the rest, and returns the counts. A mesh of one component is
// unchanged. Precondition: ids index `positions`. O(V + F). Thread-safe.
DebrisDropped DropDebris(const std::vector<Eigen::Vector3d>& positions,
                         std::vector<std::array<int32_t, 3>>* triangles,
                         const DebrisOptions& options = {});

// DebrisWarning returns the warning sentence for `dropped`.
std::string DebrisWarning(const DebrisDropped& dropped,
                          const DebrisOptions& options = {});

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_DEBRIS_H_
