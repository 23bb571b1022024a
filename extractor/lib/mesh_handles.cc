// Shortest non-separating cycles and handle cuts (see mesh_handles.h). Our
// own tree-cotree and sweeps: CGAL (Debian libcgal-dev) has shortest
// non-contractible cycles (Surface_mesh_topology), but contractible is a
// homotopy test, not the Z/2 homology one that tells a handle here, and
// it would bring CGAL's surface types into the pure library for ~200 lines.
#include "extractor/lib/mesh_handles.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <tuple>
#include <utility>

#include "absl/strings/str_cat.h"

namespace tpr::extract {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

uint64_t HalfEdgeKey(int32_t a, int32_t b) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(a)) << 32) |
         static_cast<uint32_t>(b);
}

// Per directed edge a -> b of a triangle: the triangle, sorted by key.
std::vector<std::pair<uint64_t, int32_t>> HalfEdges(const Mesh& mesh) {
  std::vector<std::pair<uint64_t, int32_t>> out;
  out.reserve(mesh.triangles.size() * 3);
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    for (int k = 0; k < 3; ++k) {
      out.push_back(
          {HalfEdgeKey(t[k], t[(k + 1) % 3]), static_cast<int32_t>(f)});
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

// FaceOf returns the triangle holding a -> b, or -1.
int32_t FaceOf(const std::vector<std::pair<uint64_t, int32_t>>& half_edges,
               int32_t a, int32_t b) {
  const uint64_t key = HalfEdgeKey(a, b);
  auto it = std::lower_bound(half_edges.begin(), half_edges.end(),
                             std::make_pair(key, int32_t{-1}));
  if (it == half_edges.end() || it->first != key) return -1;
  return it->second;
}

// The edge graph of a closed mesh with its tree-cotree crossing masks.
struct EdgeGraph {
  std::vector<std::array<int32_t, 2>> ends;   // per edge: its vertices
  std::vector<std::array<int32_t, 2>> faces;  // per edge: its two triangles
  std::vector<double> length;
  std::vector<uint64_t> mask;    // bit j: the edge lies on cocycle j
  std::vector<int64_t> offsets;  // vertex adjacency (CSR)
  std::vector<std::pair<int32_t, int32_t>> adjacent;  // (vertex, edge)
};

absl::StatusOr<EdgeGraph> BuildEdgeGraph(const Mesh& mesh) {
  const int32_t n = static_cast<int32_t>(mesh.positions.size());
  const int32_t num_faces = static_cast<int32_t>(mesh.triangles.size());
  // Undirected edges from the sorted (lo, hi, face) triples.
  struct Side {
    int32_t lo, hi, face;
  };
  std::vector<Side> sides;
  sides.reserve(static_cast<size_t>(num_faces) * 3);
  for (int32_t f = 0; f < num_faces; ++f) {
    const auto& t = mesh.triangles[f];
    for (int k = 0; k < 3; ++k) {
      const int32_t a = t[k], b = t[(k + 1) % 3];
      sides.push_back({std::min(a, b), std::max(a, b), f});
    }
  }
  std::sort(sides.begin(), sides.end(), [](const Side& x, const Side& y) {
    return std::tie(x.lo, x.hi, x.face) < std::tie(y.lo, y.hi, y.face);
  });
  EdgeGraph g;
  for (size_t i = 0; i < sides.size();) {
    size_t j = i;
    while (j < sides.size() && sides[j].lo == sides[i].lo &&
           sides[j].hi == sides[i].hi) {
      ++j;
    }
    if (j - i != 2) {
      return absl::FailedPreconditionError(absl::StrCat(
          "handles: edge (", sides[i].lo, ", ", sides[i].hi, ") has ", j - i,
          " triangles; only closed manifold meshes are searched"));
    }
    g.ends.push_back({sides[i].lo, sides[i].hi});
    g.faces.push_back({sides[i].face, sides[i + 1].face});
    g.length.push_back(
        (mesh.positions[sides[i].lo] - mesh.positions[sides[i].hi]).norm());
    i = j;
  }
  const int32_t num_edges = static_cast<int32_t>(g.ends.size());
  g.offsets.assign(n + 1, 0);
  for (const auto& e : g.ends) {
    ++g.offsets[e[0] + 1];
    ++g.offsets[e[1] + 1];
  }
  for (int32_t v = 0; v < n; ++v) g.offsets[v + 1] += g.offsets[v];
  g.adjacent.resize(g.offsets[n]);
  std::vector<int64_t> fill(g.offsets.begin(), g.offsets.end() - 1);
  for (int32_t e = 0; e < num_edges; ++e) {
    g.adjacent[fill[g.ends[e][0]]++] = {g.ends[e][1], e};
    g.adjacent[fill[g.ends[e][1]]++] = {g.ends[e][0], e};
  }

  // Tree: a BFS spanning forest of the vertices.
  std::vector<char> in_tree(num_edges, 0), seen(n, 0);
  std::vector<int32_t> queue;
  for (int32_t s = 0; s < n; ++s) {
    if (seen[s]) continue;
    seen[s] = 1;
    queue.assign(1, s);
    for (size_t q = 0; q < queue.size(); ++q) {
      const int32_t v = queue[q];
      for (int64_t k = g.offsets[v]; k < g.offsets[v + 1]; ++k) {
        const auto [w, e] = g.adjacent[k];
        if (seen[w]) continue;
        seen[w] = 1;
        in_tree[e] = 1;
        queue.push_back(w);
      }
    }
  }
  // Cotree: a BFS spanning forest of the triangles across non-tree edges.
  std::vector<std::array<int32_t, 3>> face_edges(num_faces, {-1, -1, -1});
  for (int32_t e = 0; e < num_edges; ++e) {
    for (int32_t f : g.faces[e]) {
      for (int32_t& slot : face_edges[f]) {
        if (slot < 0) {
          slot = e;
          break;
        }
      }
    }
  }
  std::vector<char> in_cotree(num_edges, 0), face_seen(num_faces, 0);
  std::vector<int32_t> parent_edge(num_faces, -1), order;
  order.reserve(num_faces);
  for (int32_t s = 0; s < num_faces; ++s) {
    if (face_seen[s]) continue;
    face_seen[s] = 1;
    size_t q = order.size();
    order.push_back(s);
    for (; q < order.size(); ++q) {
      const int32_t f = order[q];
      for (int32_t e : face_edges[f]) {
        if (in_tree[e]) continue;
        const int32_t h = g.faces[e][0] == f ? g.faces[e][1] : g.faces[e][0];
        if (face_seen[h]) continue;
        face_seen[h] = 1;
        in_cotree[e] = 1;
        parent_edge[h] = e;
        order.push_back(h);
      }
    }
  }
  // Leftover edges, one cocycle each: the edge plus the cotree path between
  // its triangles. A cotree edge above triangle f lies on cocycle j iff
  // exactly one of j's triangles is below it.
  std::vector<uint64_t> below(num_faces, 0);
  g.mask.assign(num_edges, 0);
  int leftover = 0;
  for (int32_t e = 0; e < num_edges; ++e) {
    if (in_tree[e] || in_cotree[e]) continue;
    if (leftover == 64) {
      return absl::FailedPreconditionError(
          "handles: genus above 32 (more than 64 cocycles)");
    }
    const uint64_t bit = uint64_t{1} << leftover++;
    g.mask[e] = bit;
    below[g.faces[e][0]] ^= bit;
    below[g.faces[e][1]] ^= bit;
  }
  for (size_t q = order.size(); q-- > 0;) {
    const int32_t f = order[q];
    const int32_t e = parent_edge[f];
    if (e < 0) continue;
    g.mask[e] = below[f];
    const int32_t up = g.faces[e][0] == f ? g.faces[e][1] : g.faces[e][0];
    below[up] ^= below[f];
  }
  return g;
}

// One Dijkstra sweep from `root` over the edge graph, stopped past
// `radius`, checking every non-tree edge between two settled vertices for
// a non-trivial cycle shorter than *best (updating *best, *u, *w).
class CycleSearch {
 public:
  explicit CycleSearch(const EdgeGraph& g)
      : g_(g),
        dist_(g.offsets.size() - 1, kInf),
        parent_(g.offsets.size() - 1, -1),
        path_mask_(g.offsets.size() - 1, 0),
        settled_(g.offsets.size() - 1, 0) {}

  void Sweep(int32_t root, double* best, int32_t* u, int32_t* w) {
    for (int32_t v : touched_) {
      dist_[v] = kInf;
      parent_[v] = -1;
      path_mask_[v] = 0;
      settled_[v] = 0;
    }
    touched_.clear();
    using Item = std::pair<double, int32_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<Item>> heap;
    dist_[root] = 0.0;
    touched_.push_back(root);
    heap.push({0.0, root});
    while (!heap.empty()) {
      const auto [d, v] = heap.top();
      heap.pop();
      if (settled_[v] || d > dist_[v]) continue;
      // Both ends of a cycle shorter than *best lie within *best / 2 of
      // the root (mesh_handles.h), so farther vertices cannot improve it.
      if (d > 0.5 * *best) break;
      settled_[v] = 1;
      for (int64_t k = g_.offsets[v]; k < g_.offsets[v + 1]; ++k) {
        const auto [x, e] = g_.adjacent[k];
        if (settled_[x]) {
          if (e == parent_[v] || e == parent_[x]) continue;
          if ((path_mask_[v] ^ path_mask_[x] ^ g_.mask[e]) == 0) continue;
          const double length = d + dist_[x] + g_.length[e];
          if (length < *best) {
            *best = length;
            *u = v;
            *w = x;
          }
          continue;
        }
        const double nd = d + g_.length[e];
        if (nd < dist_[x]) {
          if (dist_[x] == kInf) touched_.push_back(x);
          dist_[x] = nd;
          parent_[x] = e;
          path_mask_[x] = path_mask_[v] ^ g_.mask[e];
          heap.push({nd, x});
        }
      }
    }
  }

  // The tree path from v up to the last sweep's root, v first.
  std::vector<int32_t> PathToRoot(int32_t v) const {
    std::vector<int32_t> path = {v};
    while (parent_[v] >= 0) {
      const auto& e = g_.ends[parent_[v]];
      v = e[0] == v ? e[1] : e[0];
      path.push_back(v);
    }
    return path;
  }

 private:
  const EdgeGraph& g_;
  std::vector<double> dist_;
  std::vector<int32_t> parent_;
  std::vector<uint64_t> path_mask_;
  std::vector<char> settled_;
  std::vector<int32_t> touched_;
};

}  // namespace

absl::StatusOr<std::vector<int32_t>> ShortestNonSeparatingCycle(
    const Mesh& mesh, double* length) {
  absl::StatusOr<EdgeGraph> graph = BuildEdgeGraph(mesh);
  if (!graph.ok()) return graph.status();
  const EdgeGraph& g = *graph;
  // A non-trivial cycle crosses some cocycle, so it passes through an end
  // of an edge with a non-zero mask: those are the only roots needed.
  std::vector<int32_t> roots;
  for (size_t e = 0; e < g.mask.size(); ++e) {
    if (g.mask[e] == 0) continue;
    roots.push_back(g.ends[e][0]);
    roots.push_back(g.ends[e][1]);
  }
  std::sort(roots.begin(), roots.end());
  roots.erase(std::unique(roots.begin(), roots.end()), roots.end());
  if (roots.empty()) {
    if (length != nullptr) *length = 0.0;
    return std::vector<int32_t>{};
  }
  CycleSearch search(g);
  double best = kInf;
  int32_t best_root = -1, u = -1, w = -1;
  for (int32_t r : roots) {
    const double before = best;
    search.Sweep(r, &best, &u, &w);
    if (best < before) best_root = r;
  }
  // Sweep again from the best root (the same tree, bounded past u and w)
  // for the two paths.
  double again = kInf;
  int32_t u2 = -1, w2 = -1;
  search.Sweep(best_root, &again, &u2, &w2);
  std::vector<int32_t> a = search.PathToRoot(u), b = search.PathToRoot(w);
  std::reverse(a.begin(), a.end());  // root .. u
  std::reverse(b.begin(), b.end());  // root .. w
  // Drop the shared stem: the cycle runs from the paths' last common vertex.
  size_t k = 0;
  while (k + 1 < a.size() && k + 1 < b.size() && a[k + 1] == b[k + 1]) ++k;
  std::vector<int32_t> cycle(a.begin() + k, a.end());
  for (size_t i = b.size() - 1; i > k; --i) cycle.push_back(b[i]);
  if (length != nullptr) {
    double sum = 0.0;
    for (size_t i = 0; i < cycle.size(); ++i) {
      sum += (mesh.positions[cycle[i]] -
              mesh.positions[cycle[(i + 1) % cycle.size()]])
                 .norm();
    }
    *length = sum;
  }
  return cycle;
}

absl::Status CutAlongCycle(const std::vector<int32_t>& cycle, Mesh* mesh) {
  const size_t k = cycle.size();
  if (k < 3) {
    return absl::InvalidArgumentError(
        absl::StrCat("cut: a cycle of ", k, " vertices (at least 3)"));
  }
  const int32_t n = static_cast<int32_t>(mesh->positions.size());
  std::vector<int32_t> sorted = cycle;
  std::sort(sorted.begin(), sorted.end());
  for (size_t i = 0; i < k; ++i) {
    if (sorted[i] < 0 || sorted[i] >= n) {
      return absl::InvalidArgumentError(
          absl::StrCat("cut: cycle vertex ", sorted[i], " out of range"));
    }
    if (i > 0 && sorted[i] == sorted[i - 1]) {
      return absl::InvalidArgumentError(
          absl::StrCat("cut: cycle repeats vertex ", sorted[i]));
    }
  }
  const std::vector<std::pair<uint64_t, int32_t>> half_edges = HalfEdges(*mesh);
  for (size_t i = 0; i < k; ++i) {
    const int32_t a = cycle[i], b = cycle[(i + 1) % k];
    if (FaceOf(half_edges, a, b) < 0 || FaceOf(half_edges, b, a) < 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "cut: (", a, ", ", b, ") is not an edge of two triangles"));
    }
  }
  // Left of the cycle at c_i: the triangles around c_i from the one holding
  // c_i -> c_{i+1}, turning counter-clockwise, to the one holding
  // c_{i-1} -> c_i.
  std::vector<std::pair<int32_t, int32_t>> left;  // (triangle, vertex)
  const size_t max_steps = mesh->triangles.size();
  for (size_t i = 0; i < k; ++i) {
    const int32_t v = cycle[i], next = cycle[(i + 1) % k],
                  prev = cycle[(i + k - 1) % k];
    int32_t f = FaceOf(half_edges, v, next);
    for (size_t step = 0;; ++step) {
      if (f < 0 || step > max_steps) {
        return absl::InvalidArgumentError(absl::StrCat(
            "cut: the triangles around vertex ", v, " do not form one fan"));
      }
      left.push_back({f, v});
      const auto& t = mesh->triangles[f];
      const int at = t[0] == v ? 0 : t[1] == v ? 1 : 2;
      const int32_t third = t[(at + 2) % 3];
      if (third == prev) break;
      f = FaceOf(half_edges, v, third);
    }
  }
  std::vector<int32_t> copy(k);
  for (size_t i = 0; i < k; ++i) {
    copy[i] = static_cast<int32_t>(mesh->positions.size());
    mesh->positions.push_back(mesh->positions[cycle[i]]);
  }
  for (const auto& [f, v] : left) {
    const size_t i = static_cast<size_t>(
        std::find(cycle.begin(), cycle.end(), v) - cycle.begin());
    for (int32_t& corner : mesh->triangles[f]) {
      if (corner == v) corner = copy[i];
    }
  }
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int32_t v : cycle) centroid += mesh->positions[v];
  centroid /= static_cast<double>(k);
  const int32_t centre = static_cast<int32_t>(mesh->positions.size());
  mesh->positions.push_back(centroid);
  mesh->positions.push_back(centroid);
  for (size_t i = 0; i < k; ++i) {
    const size_t j = (i + 1) % k;
    // The original side's triangles hold c_{i+1} -> c_i: its cap holds
    // c_i -> c_{i+1}; the copies' side the reverse.
    mesh->triangles.push_back({cycle[i], cycle[j], centre});
    mesh->triangles.push_back({copy[j], copy[i], centre + 1});
  }
  return absl::OkStatus();
}

absl::StatusOr<HandleCut> CutHandles(const Mesh& mesh,
                                     const HandleCutOptions& options) {
  if (options.max_handles < 0 || options.max_handles > 32) {
    return absl::InvalidArgumentError(absl::StrCat(
        "handles: max_handles ", options.max_handles, " not in [0, 32]"));
  }
  HandleCut out;
  out.mesh = mesh;
  out.origin.resize(mesh.positions.size());
  for (size_t v = 0; v < out.origin.size(); ++v) {
    out.origin[v] = static_cast<int32_t>(v);
  }
  int64_t genus = ComputeMeshStats(mesh).genus;
  while (out.handles_cut < options.max_handles && genus > 0) {
    double length = 0.0;
    absl::StatusOr<std::vector<int32_t>> cycle =
        ShortestNonSeparatingCycle(out.mesh, &length);
    if (!cycle.ok()) return cycle.status();
    if (cycle->empty()) break;
    const absl::Status cut = CutAlongCycle(*cycle, &out.mesh);
    if (!cut.ok()) return absl::InternalError(cut.message());
    for (int32_t v : *cycle) out.origin.push_back(out.origin[v]);
    out.origin.push_back(out.origin[cycle->front()]);
    out.origin.push_back(out.origin[cycle->front()]);
    const int64_t after = ComputeMeshStats(out.mesh).genus;
    if (after != genus - 1) {
      return absl::InternalError(
          absl::StrCat("handles: cutting a cycle of ", cycle->size(),
                       " vertices took the genus from ", genus, " to ", after));
    }
    genus = after;
    ++out.handles_cut;
    out.cycle_lengths.push_back(length);
  }
  return out;
}

}  // namespace tpr::extract
