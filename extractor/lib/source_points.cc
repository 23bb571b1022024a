#include "extractor/lib/source_points.h"

#include <string>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace tpr::extract {
namespace {

// FarthestReached returns the reached vertex of largest distance in the
// last sweep; the settle order makes it the last settled vertex, and ties
// resolve to the vertex settled last, deterministically.
int32_t FarthestReached(const DijkstraSolver& solver) {
  const std::vector<int32_t>& order = solver.order();
  return order.empty() ? -1 : order.back();
}

absl::Status ValidateOptions(const IntegralGeodesicOptions& o) {
  if (o.first_level_patches < 2) {
    return absl::InvalidArgumentError(absl::StrCat(
        "first_level_patches must be at least 2, got ", o.first_level_patches));
  }
  if (o.patches_per_level < 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "patches_per_level must be at least 1, got ", o.patches_per_level));
  }
  if (!(o.min_relative_change >= 0.0)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "min_relative_change must be >= 0, got ", o.min_relative_change));
  }
  if (!(o.min_patch_area_fraction >= 0.0 && o.min_patch_area_fraction <= 1.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_patch_area_fraction must be in [0, 1], got ",
                     o.min_patch_area_fraction));
  }
  if (o.min_levels < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("min_levels must be >= 0, got ", o.min_levels));
  }
  if (o.max_sweeps < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_sweeps must be >= 1, got ", o.max_sweeps));
  }
  if (o.field_budget_bytes < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "field_budget_bytes must be >= 0, got ", o.field_budget_bytes));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<SourcePoints> SelectSourcePoints(
    const MeshGraph& graph, DijkstraSolver& solver,
    const IntegralGeodesicOptions& options) {
  absl::Status valid = ValidateOptions(options);
  if (!valid.ok()) return valid;
  if (graph.num_vertices() == 0) {
    return absl::InvalidArgumentError("mesh has no vertices");
  }
  const int32_t c = graph.largest_component();
  if (!(graph.component_areas()[c] > 0.0)) {
    return absl::InvalidArgumentError(
        "mesh has zero surface area (no triangle of positive area)");
  }
  int32_t start = -1;
  for (int32_t v = 0; v < graph.num_vertices() && start < 0; ++v) {
    if (graph.component()[v] == c) start = v;
  }

  // Double sweep (4.5, [14]): the farthest vertex from an arbitrary one,
  // then the farthest from that.
  SourcePoints s;
  solver.Run(start);
  s.far_a = FarthestReached(solver);
  const std::vector<double>& from_a = solver.Run(s.far_a);
  s.far_b = FarthestReached(solver);
  s.g_far_ab = from_a[s.far_b];
  // The sweep from far_a is the first level's first centre: its farthest
  // point sampling then takes far_b next, so G at both extremes is exact and
  // feeds MAX G.
  s.surface_centre =
      FindSurfaceCentreFrom(graph, solver, options, s.far_a, from_a);
  s.centre = s.surface_centre.vertex;
  s.sweeps = 2 + s.surface_centre.sweeps;
  return s;
}

}  // namespace tpr::extract
