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
// Every sweep's field is kept (as float: half the memory, and 7 digits are
// plenty for choosing where to look; G itself is summed in double from the
// solver's field) because Hilaga's approximation of G needs all of them.
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

    patch_.clear();
    for (int32_t v = 0; v < n; ++v) {
      if (comp[v] == c) patch_.push_back(v);
    }
    component_vertices_ = patch_;
    nearest_.assign(n, -1);
    near_dist_.assign(n, kUnreachable);
    evaluated_.assign(n, 0);
    fields_.reserve(static_cast<size_t>(options_.max_sweeps + 1) * n);
    AddCentre(seed, seed_distances);

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

      const double level_start_g = best_g_;
      // Farthest-point sampling: each new centre is the patch vertex
      // farthest from every centre so far, so the patches are the Voronoi
      // cells of the centres under graph distance.
      const int new_centres = result_.levels == 0
                                  ? options_.first_level_patches - 1
                                  : options_.patches_per_level;
      for (int i = 0; i < new_centres && result_.sweeps < options_.max_sweeps;
           ++i) {
        int32_t far = -1;
        for (int32_t v : patch_) {
          if (far < 0 || near_dist_[v] > near_dist_[far]) far = v;
        }
        if (far < 0 || !(near_dist_[far] > 0.0)) break;  // patch exhausted
        AddCentre(far, solver_.Run(far));
        ++result_.sweeps;
      }
      if (options_.approximation_guided &&
          result_.sweeps < options_.max_sweeps) {
        int32_t highest = -1;  // used once the search ends
        const int32_t guess = ApproximateExtremes(&highest);
        if (guess >= 0) {
          AddCentre(guess, solver_.Run(guess));
          ++result_.sweeps;
        }
      }
      ++result_.levels;

      // The sampling radius: every patch vertex lies within it of some
      // centre. The next patch is everything within it of the best vertex
      // (its Voronoi cell plus a margin into the neighbouring cells, so a
      // minimum just across a cell border stays inside) and of the
      // runners-up (patches_kept): G often has near-equal minima on
      // opposite sides of a tube-like torso, which one best patch would
      // lose for good.
      double radius = 0.0;
      for (int32_t v : patch_) radius = std::max(radius, near_dist_[v]);
      RankCentres();
      const size_t old_size = patch_.size();
      patch_.clear();
      const int keep = std::min<int>(std::max(1, options_.patches_kept),
                                     static_cast<int>(ranked_.size()));
      for (int32_t v : component_vertices_) {
        for (int r = 0; r < keep; ++r) {
          if (Field(ranked_[r])[v] <= radius) {
            patch_.push_back(v);
            break;
          }
        }
      }
      const size_t kept = patch_.size();

      const double change = level_start_g - best_g_;
      if (result_.levels >= options_.min_levels &&
          change < options_.min_relative_change * best_g_) {
        break;
      }
      // A level that neither improved nor shrank the patch would repeat
      // itself exactly.
      if (kept == old_size && change <= 0.0) break;
    }
    // Last, G at the approximation's maximum (built from every sweep), for
    // MAX G (Eqs. 1, 5) where no centre hit the extremity where G peaks.
    // After the search so that it cannot change the centre found.
    if (options_.refine_max && result_.sweeps < options_.max_sweeps) {
      int32_t highest = -1;
      ApproximateExtremes(&highest);
      if (highest >= 0) {
        AddCentre(highest, solver_.Run(highest));
        ++result_.sweeps;
      }
    }
    result_.vertex = centres_[best_index_];
    result_.g_min = best_g_;
    return std::move(result_);
  }

 private:
  const float* Field(int i) const {
    return fields_.data() + static_cast<size_t>(i) * graph_.num_vertices();
  }

  // AddCentre records a swept vertex: its exact G, its field, and the
  // Voronoi labels of every vertex of the component.
  void AddCentre(int32_t v, const std::vector<double>& d) {
    const int32_t n = graph_.num_vertices();
    const int index = static_cast<int>(centres_.size());
    centres_.push_back(v);
    evaluated_[v] = 1;
    const double g = IntegralGeodesicOfField(graph_, d);
    fields_.resize(fields_.size() + n);
    float* f = fields_.data() + static_cast<size_t>(index) * n;
    for (int32_t u = 0; u < n; ++u) {
      f[u] = static_cast<float>(d[u]);
      if (d[u] < near_dist_[u]) {
        near_dist_[u] = d[u];
        nearest_[u] = index;
      }
    }
    result_.evaluated_vertices.push_back(v);
    result_.evaluated_g.push_back(g);
    // The double field too, for reuse by later stages, while the budget
    // lasts (IntegralGeodesicOptions::field_budget_bytes).
    const int64_t field_bytes = static_cast<int64_t>(sizeof(double)) * n;
    if (kept_field_bytes_ + field_bytes <= options_.field_budget_bytes) {
      kept_field_bytes_ += field_bytes;
      result_.evaluated_fields.push_back(d);
    } else {
      result_.evaluated_fields.emplace_back();
    }
    if (result_.g_max_vertex < 0 || g > result_.g_max) {
      result_.g_max = g;
      result_.g_max_vertex = v;
    }
    if (best_index_ < 0 || g < best_g_) {
      best_index_ = index;
      best_g_ = g;
    }
  }

  // RankCentres orders the centres by G, smallest first (ties by order of
  // evaluation), into ranked_.
  void RankCentres() {
    ranked_.resize(centres_.size());
    for (size_t i = 0; i < ranked_.size(); ++i)
      ranked_[i] = static_cast<int>(i);
    const std::vector<double>& g = result_.evaluated_g;
    std::stable_sort(ranked_.begin(), ranked_.end(),
                     [&g](int a, int b) { return g[a] < g[b]; });
  }

  // ApproximateExtremes returns the unevaluated vertex minimising Hilaga
  // et al.'s [9] approximation G~(p) = sum_i area(cell_i) g_i(p), the
  // integral with each Voronoi cell collapsed onto its centre, and sets
  // *highest to the unevaluated vertex maximising it over the component;
  // -1 when there is none. The minimum is sought over the component or the
  // patch (approximation_global). |G~(p) - G(p)| is at most
  // sum_i int_{cell_i} d(x, c_i), uniformly in p, which is what makes its
  // minimum land in the right basin when farthest-point centres alone
  // (which favour extremities) miss it. O(centres * n).
  int32_t ApproximateExtremes(int32_t* highest) {
    const std::vector<double>& area = graph_.vertex_areas();
    cell_area_.assign(centres_.size(), 0.0);
    for (int32_t v = 0; v < graph_.num_vertices(); ++v) {
      if (nearest_[v] >= 0) cell_area_[nearest_[v]] += area[v];
    }
    const std::vector<int32_t>& where = component_vertices_;
    approx_.assign(where.size(), 0.0);
    for (size_t i = 0; i < centres_.size(); ++i) {
      const double a = cell_area_[i];
      if (a == 0.0) continue;
      const float* f = Field(static_cast<int>(i));
      for (size_t j = 0; j < where.size(); ++j) approx_[j] += a * f[where[j]];
    }
    if (!options_.approximation_global) {
      in_patch_.assign(graph_.num_vertices(), 0);
      for (int32_t v : patch_) in_patch_[v] = 1;
    }
    int32_t best = -1;
    double best_value = kUnreachable;
    *highest = -1;
    double high_value = -kUnreachable;
    for (size_t j = 0; j < where.size(); ++j) {
      const int32_t v = where[j];
      if (evaluated_[v]) continue;
      if (approx_[j] > high_value) {
        high_value = approx_[j];
        *highest = v;
      }
      if (!options_.approximation_global && !in_patch_[v]) continue;
      if (approx_[j] < best_value) {
        best_value = approx_[j];
        best = v;
      }
    }
    return best;
  }

  const MeshGraph& graph_;
  DijkstraSolver& solver_;
  const IntegralGeodesicOptions& options_;
  SurfaceCentre result_;
  std::vector<int32_t> centres_;
  std::vector<float> fields_;  // centres_.size() x n, row per centre
  std::vector<int32_t> nearest_;
  std::vector<double> near_dist_;
  std::vector<char> evaluated_;
  std::vector<int32_t> patch_;
  std::vector<int32_t> component_vertices_;
  std::vector<int> ranked_;
  std::vector<char> in_patch_;
  std::vector<double> cell_area_;
  std::vector<double> approx_;
  int best_index_ = -1;
  double best_g_ = 0.0;
  int64_t kept_field_bytes_ = 0;
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

const std::vector<double>* KeptField(const SurfaceCentre& centre, int32_t v) {
  for (size_t i = 0; i < centre.evaluated_vertices.size() &&
                     i < centre.evaluated_fields.size();
       ++i) {
    if (centre.evaluated_vertices[i] == v) {
      return centre.evaluated_fields[i].empty() ? nullptr
                                                : &centre.evaluated_fields[i];
    }
  }
  return nullptr;
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
