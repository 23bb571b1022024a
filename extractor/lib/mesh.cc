// ComputeMeshStats: counts, area, boundary, components and genus of an
// indexed triangle mesh.
#include "extractor/lib/mesh.h"

#include <Eigen/Geometry>  // cross(): declared in Core, defined here.
#include <algorithm>
#include <cassert>
#include <cstdint>
#include <numeric>
#include <utility>
#include <vector>

#include "extractor/lib/disjoint_sets.h"

namespace tpr::extract {

MeshStats ComputeMeshStats(const Mesh& mesh) {
  MeshStats stats;
  const int64_t num_vertices = static_cast<int64_t>(mesh.positions.size());
  const int64_t num_faces = static_cast<int64_t>(mesh.triangles.size());
  stats.vertices = num_vertices;
  stats.faces = num_faces;
  if (num_faces == 0) return stats;

  // Undirected edges as (key, face) pairs, sorted so that each edge's faces
  // are adjacent: O(F log F), and no hash table to tune.
  std::vector<std::pair<uint64_t, int64_t>> edges;
  edges.reserve(3 * num_faces);
  for (int64_t f = 0; f < num_faces; ++f) {
    const auto& t = mesh.triangles[f];
    const Eigen::Vector3d& a = mesh.positions[t[0]];
    stats.area +=
        0.5 * (mesh.positions[t[1]] - a).cross(mesh.positions[t[2]] - a).norm();
    for (int k = 0; k < 3; ++k) {
      uint32_t u = static_cast<uint32_t>(t[k]);
      uint32_t v = static_cast<uint32_t>(t[(k + 1) % 3]);
      assert(u < static_cast<uint64_t>(num_vertices) &&
             v < static_cast<uint64_t>(num_vertices));
      if (u > v) std::swap(u, v);
      edges.emplace_back((static_cast<uint64_t>(u) << 32) | v, f);
    }
  }
  std::sort(edges.begin(), edges.end());

  // Faces sharing an edge are in one component; boundary edges join their
  // endpoints into boundary loops.
  DisjointSets face_sets(num_faces);
  DisjointSets vertex_sets(num_vertices);
  std::vector<std::pair<uint64_t, int64_t>> boundary;      // (edge key, face)
  std::vector<std::pair<uint64_t, int64_t>> unique_edges;  // (key, face)
  for (size_t i = 0; i < edges.size();) {
    size_t j = i + 1;
    while (j < edges.size() && edges[j].first == edges[i].first) {
      face_sets.Union(edges[i].second, edges[j].second);
      ++j;
    }
    unique_edges.push_back(edges[i]);
    if (j - i == 1) {
      boundary.push_back(edges[i]);
      vertex_sets.Union(static_cast<int64_t>(edges[i].first >> 32),
                        static_cast<int64_t>(edges[i].first & 0xffffffffu));
    }
    i = j;
  }
  stats.boundary_edges = static_cast<int64_t>(boundary.size());

  // Per-component V, E, F, B, indexed by the component's root face.
  std::vector<int64_t> comp_v(num_faces, 0), comp_e(num_faces, 0),
      comp_f(num_faces, 0), comp_b(num_faces, 0);
  std::vector<int64_t> vertex_comp(num_vertices, -1);
  for (int64_t f = 0; f < num_faces; ++f) {
    const int64_t root = face_sets.Find(f);
    ++comp_f[root];
    for (int32_t v : mesh.triangles[f]) {
      if (vertex_comp[v] < 0) {
        vertex_comp[v] = root;
        ++comp_v[root];
      }
    }
  }
  for (const auto& e : unique_edges) ++comp_e[face_sets.Find(e.second)];
  std::vector<char> loop_counted(num_vertices, 0);
  for (const auto& e : boundary) {
    const int64_t loop = vertex_sets.Find(static_cast<int64_t>(e.first >> 32));
    if (!loop_counted[loop]) {
      loop_counted[loop] = 1;
      ++comp_b[face_sets.Find(e.second)];
    }
  }
  for (int64_t f = 0; f < num_faces; ++f) {
    if (comp_f[f] == 0) continue;
    ++stats.components;
    // Euler-Poincare with boundary: V - E + F = 2 - 2g - B.
    stats.genus += (2 - comp_v[f] + comp_e[f] - comp_f[f] - comp_b[f]) / 2;
  }
  return stats;
}

}  // namespace tpr::extract
