#include "extractor/lib/debris.h"

#include <Eigen/Geometry>

#include "absl/strings/str_cat.h"
#include "extractor/lib/disjoint_sets.h"

namespace tpr::extract {

DebrisDropped DropDebris(const std::vector<Eigen::Vector3d>& positions,
                         std::vector<std::array<int32_t, 3>>* triangles,
                         const DebrisOptions& options) {
  DebrisDropped dropped;
  if (triangles->empty()) return dropped;
  DisjointSets sets(positions.size());
  for (const auto& t : *triangles) {
    sets.Union(t[0], t[1]);
    sets.Union(t[0], t[2]);
  }
  // Per component root: area, and vertices (each referenced vertex counted
  // once, at its first triangle).
  std::vector<double> area(positions.size(), 0.0);
  std::vector<int64_t> vertices(positions.size(), 0);
  std::vector<char> seen(positions.size(), 0);
  for (const auto& t : *triangles) {
    const int64_t root = sets.Find(t[0]);
    area[root] += 0.5 * (positions[t[1]] - positions[t[0]])
                            .cross(positions[t[2]] - positions[t[0]])
                            .norm();
    for (int32_t v : t) {
      if (!seen[v]) {
        seen[v] = 1;
        ++vertices[root];
      }
    }
  }
  int64_t largest = -1;
  int64_t components = 0;
  for (size_t r = 0; r < positions.size(); ++r) {
    if (vertices[r] == 0) continue;
    ++components;
    if (largest < 0 || area[r] > area[largest])
      largest = static_cast<int64_t>(r);
  }
  if (components <= 1) return dropped;
  const double max_area = options.area_fraction * area[largest];
  const double max_vertices =
      options.vertex_fraction * static_cast<double>(vertices[largest]);
  std::vector<char> debris(positions.size(), 0);
  for (size_t r = 0; r < positions.size(); ++r) {
    if (vertices[r] == 0 || static_cast<int64_t>(r) == largest) continue;
    if (area[r] < max_area && static_cast<double>(vertices[r]) < max_vertices) {
      debris[r] = 1;
      ++dropped.components;
      dropped.vertices += vertices[r];
    }
  }
  if (dropped.components == 0) return dropped;
  size_t kept = 0;
  for (size_t i = 0; i < triangles->size(); ++i) {
    const auto& t = (*triangles)[i];
    if (debris[sets.Find(t[0])]) {
      ++dropped.triangles;
      continue;
    }
    (*triangles)[kept++] = t;
  }
  triangles->resize(kept);
  return dropped;
}

std::string DebrisWarning(const DebrisDropped& dropped,
                          const DebrisOptions& options) {
  return absl::StrCat("dropped ", dropped.components, " debris components (",
                      dropped.triangles, " triangles, ", dropped.vertices,
                      " vertices): each under ", options.area_fraction * 100,
                      "% of the largest component's area and ",
                      options.vertex_fraction * 100, "% of its vertices");
}

}  // namespace tpr::extract
