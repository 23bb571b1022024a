#include "extractor/lib/integral_geodesic.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <utility>

namespace tpr::extract {
namespace {

// LowestVertexOf returns the smallest vertex id in component `c`, -1 if none.
int32_t LowestVertexOf(const MeshGraph& graph, int32_t c) {
  const std::vector<int32_t>& comp = graph.component();
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if (comp[v] == c) return v;
  }
  return -1;
}

// HierarchicalSearch holds the state of one surface-centre search (4.5).
// Per-vertex scratch is flat and sized once; the patch is a vertex list.
class HierarchicalSearch {
 public:
  HierarchicalSearch(const MeshGraph& graph, DijkstraSolver& solver,
                     const IntegralGeodesicOptions& options)
      : graph_(graph), solver_(solver), options_(options) {}

  SurfaceCentre Run(int32_t seed, const std::vector<double>& seed_distances,
                    int seed_sweeps) {
    const int32_t n = graph_.num_vertices();
    const std::vector<int32_t>& comp = graph_.component();
    const std::vector<double>& area = graph_.vertex_areas();
    const int32_t c = comp[seed];
    const double component_area = graph_.component_areas()[c];
    result_.sweeps = seed_sweeps;

    best_field_ = seed_distances;
    best_vertex_ = seed;
    best_g_ = IntegralGeodesicOfField(graph_, best_field_);
    Record(seed, best_g_);

    patch_.clear();
    for (int32_t v = 0; v < n; ++v) {
      if (comp[v] == c) patch_.push_back(v);
    }
    min_dist_.assign(n, kUnreachable);
    const int k = std::max(2, options_.patches_per_level);

    while (true) {
      double patch_area = 0.0;
      for (int32_t v : patch_) patch_area += area[v];
      // "... or the patch area is too small" (4.5). The whole component is
      // always split once.
      if (result_.levels > 0 &&
          patch_area < options_.min_patch_area_fraction * component_area) {
        break;
      }
      if (patch_.size() <= 1 || result_.sweeps >= options_.max_sweeps) break;

      // Farthest-point sampling of the patch's centres; the current best is
      // the first centre, its field known. min_dist_ over the patch is the
      // distance to the nearest centre, so the patches are the centres'
      // Voronoi cells under graph distance.
      for (int32_t v : patch_) min_dist_[v] = best_field_[v];
      const double level_start_g = best_g_;
      int32_t level_best = best_vertex_;
      double level_best_g = best_g_;
      bool level_best_is_new = false;
      for (int i = 1; i < k && result_.sweeps < options_.max_sweeps; ++i) {
        int32_t far = -1;
        for (int32_t v : patch_) {
          if (far < 0 || min_dist_[v] > min_dist_[far]) far = v;
        }
        if (far < 0 || !(min_dist_[far] > 0.0)) break;  // patch exhausted
        const std::vector<double>& d = solver_.Run(far);
        ++result_.sweeps;
        const double g = IntegralGeodesicOfField(graph_, d);
        Record(far, g);
        for (int32_t v : patch_) min_dist_[v] = std::min(min_dist_[v], d[v]);
        if (g < level_best_g) {
          level_best = far;
          level_best_g = g;
          level_best_is_new = true;
          scratch_field_ = d;  // keeps capacity after the first copy
        }
      }
      // The sampling radius: every patch vertex lies within it of some
      // centre. The next patch is everything within it of the best centre:
      // the best Voronoi cell plus a margin into its neighbours, so that a
      // minimum just across a cell border stays inside (robustness).
      double radius = 0.0;
      for (int32_t v : patch_) radius = std::max(radius, min_dist_[v]);
      if (level_best_is_new) {
        std::swap(best_field_, scratch_field_);
        best_vertex_ = level_best;
        best_g_ = level_best_g;
      }
      ++result_.levels;
      const size_t old_size = patch_.size();
      size_t kept = 0;
      for (int32_t v : patch_) {
        if (best_field_[v] <= radius) patch_[kept++] = v;
      }
      patch_.resize(kept);

      const double change = level_start_g - best_g_;
      if (result_.levels >= options_.min_levels &&
          change < options_.min_relative_change * best_g_) {
        break;
      }
      // A level that neither improved nor shrank the patch would repeat
      // itself exactly.
      if (kept == old_size && change <= 0.0) break;
    }
    result_.vertex = best_vertex_;
    result_.g_min = best_g_;
    return std::move(result_);
  }

 private:
  void Record(int32_t v, double g) {
    result_.evaluated_vertices.push_back(v);
    result_.evaluated_g.push_back(g);
    if (result_.g_max_vertex < 0 || g > result_.g_max) {
      result_.g_max = g;
      result_.g_max_vertex = v;
    }
  }

  const MeshGraph& graph_;
  DijkstraSolver& solver_;
  const IntegralGeodesicOptions& options_;
  SurfaceCentre result_;
  std::vector<double> best_field_;
  std::vector<double> scratch_field_;
  std::vector<double> min_dist_;
  std::vector<int32_t> patch_;
  int32_t best_vertex_ = -1;
  double best_g_ = 0.0;
};

}  // namespace

double IntegralGeodesicOfField(const MeshGraph& graph,
                               const std::vector<double>& distances) {
  const std::vector<double>& area = graph.vertex_areas();
  double sum = 0.0;
  for (size_t v = 0; v < distances.size(); ++v) {
    const double d = distances[v];
    if (d != kUnreachable) sum += d * area[v];
  }
  return sum;
}

double IntegralGeodesic(DijkstraSolver& solver, int32_t q) {
  return IntegralGeodesicOfField(solver.graph(), solver.Run(q));
}

SurfaceCentre FindSurfaceCentreFrom(const MeshGraph& graph,
                                    DijkstraSolver& solver,
                                    const IntegralGeodesicOptions& options,
                                    int32_t seed,
                                    const std::vector<double>& seed_distances) {
  assert(seed >= 0 && seed < graph.num_vertices());
  assert(seed_distances.size() == static_cast<size_t>(graph.num_vertices()));
  HierarchicalSearch search(graph, solver, options);
  return search.Run(seed, seed_distances, /*seed_sweeps=*/0);
}

SurfaceCentre FindSurfaceCentre(const MeshGraph& graph, DijkstraSolver& solver,
                                const IntegralGeodesicOptions& options) {
  const int32_t c = graph.largest_component();
  if (c < 0) return SurfaceCentre{};
  const int32_t seed = LowestVertexOf(graph, c);
  // The search copies the seed's field before its first sweep, so the
  // solver's own buffer may be passed.
  HierarchicalSearch search(graph, solver, options);
  return search.Run(seed, solver.Run(seed), /*seed_sweeps=*/1);
}

SurfaceCentre BruteForceSurfaceCentre(const MeshGraph& graph,
                                      DijkstraSolver& solver) {
  SurfaceCentre r;
  const int32_t c = graph.largest_component();
  if (c < 0) return r;
  const std::vector<int32_t>& comp = graph.component();
  for (int32_t v = 0; v < graph.num_vertices(); ++v) {
    if (comp[v] != c) continue;
    const double g = IntegralGeodesic(solver, v);
    ++r.sweeps;
    r.evaluated_vertices.push_back(v);
    r.evaluated_g.push_back(g);
    if (r.vertex < 0 || g < r.g_min) {
      r.vertex = v;
      r.g_min = g;
    }
    if (r.g_max_vertex < 0 || g > r.g_max) {
      r.g_max_vertex = v;
      r.g_max = g;
    }
  }
  return r;
}

}  // namespace tpr::extract
