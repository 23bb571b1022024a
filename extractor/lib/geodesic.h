// Geodesics on a triangle mesh by Dijkstra over the edge graph (Tam & Lau
// 2007, 4.1-4.2: "LSD uses the Dijkstra algorithm to approximate the geodesic
// distance"), single source, multi source with start times (Eq. 1, 4.6) and
// from a vertex set (5.1, g_vs).
//
//   MeshGraph graph = MeshGraph::Build(mesh);          // once per mesh
//   DijkstraSolver solver(graph);                       // once per thread
//   const std::vector<double>& d = solver.Run(source);  // buffers reused
#ifndef TPR_EXTRACTOR_LIB_GEODESIC_H_
#define TPR_EXTRACTOR_LIB_GEODESIC_H_

#include <cstdint>
#include <limits>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "extractor/lib/mesh.h"
#include "extractor/lib/vertex_links.h"

namespace tpr::extract {

// kUnreachable is the distance of a vertex no wavefront reaches (another
// connected component, or beyond RunOptions::max_distance).
inline constexpr double kUnreachable = std::numeric_limits<double>::infinity();

// GeodesicOptions controls how the mesh graph approximates the surface metric.
struct GeodesicOptions {
  // Adds, for every interior edge (a, b) with opposite vertices c and d, the
  // arc (c, d) whose length is the straight line across the two triangles
  // unfolded into the plane, when that line crosses the open edge (a, b).
  // Each such length is the length of a real path on the surface, so
  // distances stay upper bounds of the polyhedral geodesic, only tighter
  // than plain edge paths, which zig-zag. Measured against the analytic
  // geodesic (tests/extractor/geodesic_test.cc): unit icospheres of 162 to
  // 10k vertices, mean relative error 6-8% -> 0.6-1.5%, max 21-22% -> 3-5%;
  // open tube, mean 10% -> 2.3%, max 18% -> 4.6%. Cost: twice the arcs,
  // so more time per sweep (BM_Dijkstra against BM_DijkstraPlainEdges;
  // figures in docs/benchmarks.md).
  // The paper uses plain Dijkstra (4.2); the zig-zag error depends on edge
  // directions, hence on tessellation and pose, and removing most of it
  // from G, ring lengths and geodesic bands is worth the sweep cost. Only
  // distances change: one_ring() never includes these arcs. Default true.
  bool unfold_opposite_edges = true;
};

// MeshGraph is the mesh's undirected edge graph in compressed sparse rows
// with edge lengths, plus each vertex's area (one third of the area of its
// incident triangles) and connected components. Immutable after Build;
// thread-safe to share between solvers.
class MeshGraph {
 public:
  MeshGraph() = default;

  // Build returns the graph of `mesh`. Precondition: every triangle index is
  // in [0, positions.size()) and every coordinate is finite (intake,
  // mesh_io.h, guarantees it; use Create for unchecked meshes). Vertices
  // without triangles become isolated vertices of area 0. Thread-safe.
  // Cost O(n + f) time (2 to 3 sweeps' worth: BM_BuildGraph against
  // BM_Dijkstra), O(e) memory.
  static MeshGraph Build(const Mesh& mesh, const GeodesicOptions& options = {});

  // Create checks the precondition of Build and then builds. Errors:
  // INVALID_ARGUMENT naming the first out-of-range index or non-finite
  // coordinate, or for a mesh with no vertex.
  static absl::StatusOr<MeshGraph> Create(const Mesh& mesh,
                                          const GeodesicOptions& options = {});

  int32_t num_vertices() const {
    return static_cast<int32_t>(offsets_.empty() ? 0 : offsets_.size() - 1);
  }
  // Number of directed adjacency entries (twice the undirected edges).
  int64_t num_arcs() const { return static_cast<int64_t>(targets_.size()); }

  // neighbors returns the vertices adjacent to v (mesh edges, plus unfolded
  // shortcuts when enabled; unordered: see one_ring for the fan order).
  // Precondition 0 <= v < num_vertices().
  absl::Span<const int32_t> neighbors(int32_t v) const {
    return absl::MakeConstSpan(targets_.data() + offsets_[v],
                               offsets_[v + 1] - offsets_[v]);
  }
  // lengths returns the edge lengths parallel to neighbors(v).
  absl::Span<const double> lengths(int32_t v) const {
    return absl::MakeConstSpan(lengths_.data() + offsets_[v],
                               offsets_[v + 1] - offsets_[v]);
  }

  // links returns the mesh's 1-ring structure (vertex_links.h): link edges,
  // sorted neighbours and fans, mesh edges only (never the unfolded
  // shortcuts). Built once with the graph; the extraction's stages share it.
  const VertexLinks& links() const { return links_; }

  // one_ring returns v's mesh-edge neighbours only (never the unfolded
  // shortcuts), in the cyclic order of v's triangle fan: links().fan(v)
  // (see VertexLinks for boundary and non-manifold fans). This is the
  // neighbourhood for level-set work (cross-edges, sign changes around a
  // saddle, 4.2-4.3); use neighbors() for distances.
  absl::Span<const int32_t> one_ring(int32_t v) const { return links_.fan(v); }

  // vertex_areas: per vertex, one third of the area of its triangles. Their
  // sum is total_area().
  const std::vector<double>& vertex_areas() const { return vertex_areas_; }
  double total_area() const { return total_area_; }

  // component: per vertex, its connected component id in [0,
  // num_components()), numbered in order of lowest vertex id.
  const std::vector<int32_t>& component() const { return component_; }
  int32_t num_components() const { return num_components_; }
  // component_areas: total vertex area per component.
  const std::vector<double>& component_areas() const {
    return component_areas_;
  }
  // largest_component: the component with the largest area (lowest id on
  // ties); -1 for an empty graph.
  int32_t largest_component() const;

  const Mesh& mesh() const { return *mesh_; }

 private:
  const Mesh* mesh_ = nullptr;  // Not owned; must outlive the graph.
  std::vector<int64_t> offsets_;
  std::vector<int32_t> targets_;
  std::vector<double> lengths_;
  VertexLinks links_;
  std::vector<double> vertex_areas_;
  double total_area_ = 0.0;
  std::vector<int32_t> component_;
  std::vector<double> component_areas_;
  int32_t num_components_ = 0;
};

// RunOptions bounds one sweep.
struct RunOptions {
  // Vertices farther than this are left unreached (kUnreachable, nearest
  // source -1, not in order()); the sweep then costs only what it visits
  // (Topological Point Selection stops at its search radius, 7.3.2).
  // Default: unbounded.
  double max_distance = kUnreachable;
};

// DijkstraSolver runs Dijkstra sweeps over one MeshGraph, reusing its buffers:
// per-vertex arrays are sized once, and the heap's buckets only grow to the
// largest size a sweep has needed, so after a few sweeps none allocates
// (tested). The graph must outlive the solver.
// Not thread-safe: use one solver per thread (the graph may be shared).
class DijkstraSolver {
 public:
  explicit DijkstraSolver(const MeshGraph& graph);

  // Run computes graph distances from one source vertex and returns
  // distances(): a reference to the solver's buffer, valid as long as the
  // solver, whose contents the next Run overwrites (copy to keep).
  // Precondition 0 <= source < num_vertices(). Unreached vertices get
  // kUnreachable. Cost O(e + n log n) for the component, less when bounded.
  const std::vector<double>& Run(int32_t source, const RunOptions& run = {});

  // Run (multi source) computes, per vertex, min over i of
  // initial_values[i] + d(sources[i], v): the wavefronts start at their
  // sources at times initial_values (Eq. 1, 4.6.1). Empty initial_values
  // means all zero, which gives the geodesic from the vertex set (g_vs,
  // 5.1). Preconditions: every source in range; initial_values empty or of
  // the same size as sources, all finite. Duplicate sources are allowed (the
  // smaller start wins, the earlier one on equal starts). An empty `sources`
  // leaves every vertex unreached. A vertex at equal distance from two
  // wavefronts goes to the one that reached it first.
  const std::vector<double>& Run(absl::Span<const int32_t> sources,
                                 absl::Span<const double> initial_values = {},
                                 const RunOptions& run = {});

  // distances: per vertex, the result of the last Run.
  const std::vector<double>& distances() const { return dist_; }
  // nearest_source: per vertex, the index into the last Run's `sources` of
  // the wavefront that reached it (0 for the single-source Run), -1 when
  // unreached.
  const std::vector<int32_t>& nearest_source() const { return source_; }
  // order: the reached vertices in the order they were settled, that is by
  // non-decreasing distance.
  const std::vector<int32_t>& order() const { return order_; }
  // parent: per vertex, the neighbour it was reached from (-1 for a source
  // whose own start time is its distance, and for unreached vertices);
  // follows shortest paths back to a source.
  const std::vector<int32_t>& parent() const { return parent_; }

  const MeshGraph& graph() const { return *graph_; }

 private:
  struct HeapEntry {
    uint64_t key;  // the distance's order-preserving bit pattern
    int32_t vertex;
  };
  void Reset();
  void Push(double key, int32_t vertex);
  // Pop removes a smallest entry; sets *key to its distance.
  int32_t Pop(double* key);
  bool HeapEmpty() const { return heap_size_ == 0; }

  const MeshGraph* graph_;
  std::vector<double> dist_;
  std::vector<int32_t> source_;
  std::vector<int32_t> parent_;
  std::vector<int32_t> order_;
  // Vertices whose dist_ was written by the last bounded Run: reset touches
  // only these, so a bounded sweep costs what it visits. An unbounded Run
  // settles every vertex it touches, so order_ lists them and touched_ is
  // not kept (reset_from_order_).
  std::vector<int32_t> touched_;
  bool reset_from_order_ = false;
  // Radix heap with lazy deletion (stale entries skipped on pop): Dijkstra
  // pops keys in non-decreasing order, so entries sit in bucket i by the
  // highest bit in which their key differs from the last popped key, and
  // each entry moves to a lower bucket at most 64 times. Buckets keep their
  // capacity across runs.
  std::vector<HeapEntry> buckets_[65];
  // Bit i - 1 is set when bucket i (1 to 64) is not empty: Pop finds the
  // next bucket with one instruction instead of testing up to 64 empty
  // ones (Dijkstra's keys differ in low mantissa bits, so it is usually
  // far down).
  uint64_t nonempty_ = 0;
  uint64_t last_key_ = 0;
  size_t heap_size_ = 0;
};

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_GEODESIC_H_
