// Integral geodesic G (Tam & Lau 2007, 4.1; Hilaga et al. [9]) and the
// surface centre, the vertex of minimum G, found by the paper's hierarchical
// patch search (4.5) rather than by a sweep from every vertex.
//
//   DijkstraSolver solver(graph);
//   SurfaceCentre c =
//       FindSurfaceCentre(graph, solver, IntegralGeodesicOptions{});
//   double g = IntegralGeodesic(solver, some_vertex);   // one sweep
#ifndef TPR_EXTRACTOR_LIB_INTEGRAL_GEODESIC_H_
#define TPR_EXTRACTOR_LIB_INTEGRAL_GEODESIC_H_

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "extractor/lib/geodesic.h"

namespace tpr::extract {

// IntegralGeodesicOptions controls the hierarchical surface-centre search
// (4.5). The paper gives no numbers except "psi ~ 20" integral geodesics on
// average (Table 4); the defaults were tuned on the generated shapes of
// tpr_synth against the brute-force minimum (integral_geodesic_test.cc) and
// land near that. Error of the min G found, as a fraction of (MAX G - MIN G)
// (the scale of Eq. 5), over the 10 classes at 1200 vertices, poses 0, 2, 5
// (used for tuning): mean 0.10%, worst 0.94%, 23.8 sweeps on average
// including the double sweep; poses 1, 3, 7 (held out): mean 0.11%, worst
// 0.89%, 24.7 sweeps; MAX G short of the true maximum by at most 0.5%.
// at 3000 vertices (poses 0, 2, 5) mean 0.14%, worst 1.2%, 24.7 sweeps,
// MAX G within 0.4%. For comparison on
// poses 0, 2, 5: the paper's scheme alone (one kept patch, no
// approximation, stop at the first level that does not improve) mean 2.8%,
// worst 39% (an octopus whose first centres are all arm tips); with the
// approximation but one kept patch, worst 1.7% (a biped whose torso has
// near-equal minima front and back).
struct IntegralGeodesicOptions {
  // Patches the whole surface is first split into (farthest-point centres;
  // the double sweep's far_a is the first). Default 8.
  int first_level_patches = 8;
  // New patch centres per deeper level, inside the current patch. Default 4.
  int patches_per_level = 4;
  // Per level, also evaluate G at the minimum of Hilaga et al.'s [9]
  // approximation of G built from every sweep so far (G~(p) = sum over
  // centres c of area(Voronoi cell of c) * g_c(p)): one sweep more per level
  // that points at the basin of the minimum, where farthest-point centres
  // crowd the patch's rim. Default true.
  bool approximation_guided = true;
  // Look for that approximate minimum over the whole surface rather than
  // the current patch, so a level can still jump to another basin the
  // patch recursion lost. Default true.
  bool approximation_global = true;
  // After the first split, also evaluate G at the maximum of that
  // approximation (one sweep), so that MAX G (Eqs. 1, 5) does not depend on
  // the first centres having hit the right extremity. Default true.
  bool refine_max = true;
  // The next level's patch surrounds this many of the best centres so far
  // (the paper keeps 1): near-equal minima of G, as on the two sides of a
  // torso, then both stay in play until one is clearly better. Default 2.
  int patches_kept = 2;
  // Stop when a level lowers min G by less than this fraction of min G
  // ("the change in the smallest integral geodesic is less than a
  // threshold", 4.5). Default 1e-3.
  double min_relative_change = 1e-3;
  // Stop when the patch to split has less than this fraction of the surface
  // area ("or the patch area is too small", 4.5). Default 2e-3.
  double min_patch_area_fraction = 2e-3;
  // Refine at least this many levels (the first included) before the change
  // test may stop the search: a level whose new centres miss the old best's
  // basin would otherwise end it. Default 3.
  int min_levels = 3;
  // Hard cap on sweeps spent by the search (bad input never hangs).
  // Default 40.
  int max_sweeps = 40;
  // Bytes of full-precision (double) distance fields the search may hand
  // back in SurfaceCentre::evaluated_fields, so that later stages (the
  // topological points' feature sweeps, 5.1/5.3) reuse the field of a vertex
  // the search already swept instead of sweeping from it again. Fields are
  // kept in sweep order while their total (8 bytes x num_vertices each)
  // stays within this budget; the rest are dropped and those vertices fall
  // back to a fresh sweep, so memory stays bounded on huge meshes. Cost: one
  // n-double copy per kept sweep and up to this many bytes held until the
  // caller drops the result; at 10k vertices about 26 fields = 2.1 MB,
  // saving one Dijkstra sweep (about 1.1 ms) per reused point. 0 keeps
  // none. Default 64 MiB (every field up to about 300k vertices).
  int64_t field_budget_bytes = int64_t{64} << 20;
};

// IntegralGeodesic returns G(q) = sum over vertices p of g_q(p) * area(p),
// with area(p) one third of p's incident triangle areas: the area-weighted
// discretization of the integral of 4.1, as Hilaga et al. [9] weight it.
// Vertices that q cannot reach (other components) contribute nothing, so G
// is the integral over q's component. Leaves the sweep from q in `solver`
// (distances(), order()). Precondition 0 <= q < num_vertices().
// Cost: one Dijkstra sweep. Not thread-safe per solver.
double IntegralGeodesic(DijkstraSolver& solver, int32_t q);

// IntegralGeodesicOfField returns sum_p distances[p] * area(p) over reached
// vertices: G of the source of a sweep already run. O(n).
double IntegralGeodesicOfField(const MeshGraph& graph,
                               const std::vector<double>& distances);

// SurfaceCentre is the result of the hierarchical search.
struct SurfaceCentre {
  // The vertex of smallest G found: the surface centre o (4.1, 4.5).
  int32_t vertex = -1;
  // G(vertex), exact (one full sweep): MIN_{q in S} G(q) of Eqs. 1 and 5.
  double g_min = 0.0;
  // MAX G estimate for Eqs. 1 and 5: the largest exact G among every vertex
  // the search swept. The first level's farthest-point centres start at a
  // double-sweep extreme and take the shape's extremities first, where G
  // peaks, and (refine_max) one last sweep goes to the maximum of Hilaga's
  // approximate G built from all sweeps. A lower bound of the true maximum
  // (measured within 0.5% of the range on generated shapes); callers should
  // raise it with G of their own candidates (topological points, 4.4) so
  // that Eq. 1 is never negative.
  double g_max = 0.0;
  int32_t g_max_vertex = -1;
  // Dijkstra sweeps spent by the search (psi of Table 4).
  int sweeps = 0;
  // Levels of refinement done.
  int levels = 0;
  // Every vertex whose G was computed, with its G (for reuse and tests).
  std::vector<int32_t> evaluated_vertices;
  std::vector<double> evaluated_g;
  // Parallel to evaluated_vertices: the full distance field of the sweep
  // from that vertex, exactly as DijkstraSolver::Run(vertex) returns it (bit
  // for bit: the same solver run from the same source), or empty where the
  // field did not fit IntegralGeodesicOptions::field_budget_bytes.
  std::vector<std::vector<double>> evaluated_fields;
};

// KeptField returns the field `centre` kept for vertex v
// (SurfaceCentre::evaluated_fields), or nullptr when v was not swept or its
// field was not kept. O(evaluated vertices). Thread-safe (read only).
const std::vector<double>* KeptField(const SurfaceCentre& centre, int32_t v);

// FindSurfaceCentre runs the hierarchical search of 4.5 on the largest
// component (by area): split the current patch into patches by
// farthest-point sampling (patches are the Voronoi cells of the centres
// under graph distance), compute G at each centre (and, when
// approximation_guided, at the minimum of the approximate G field), then
// recurse into the patch around the best vertices (patches_kept of them;
// each one's cell plus the margin up to the sampling radius, so a minimum
// just across a cell border is not lost), until the change in min G or the
// patch area is small. Starts from
// a vertex of the largest component. Returns vertex -1 for a graph with no
// vertex. Cost: `sweeps` Dijkstra sweeps (about 20-30 with the defaults)
// plus O(sweeps * n) arithmetic; memory sweeps * n floats, plus the kept
// double fields (at most options.field_budget_bytes). Not thread-safe per
// solver.
SurfaceCentre FindSurfaceCentre(const MeshGraph& graph, DijkstraSolver& solver,
                                const IntegralGeodesicOptions& options);

// FindSurfaceCentreFrom is FindSurfaceCentre with the first level seeded at
// `seed`, whose full distance field `seed_distances` (a sweep from seed) the
// caller already has: SelectSourcePoints passes the first double-sweep
// extreme, saving a sweep. seed_distances may be solver.distances() (it is
// copied before the first sweep). The search stays in seed's component.
SurfaceCentre FindSurfaceCentreFrom(const MeshGraph& graph,
                                    DijkstraSolver& solver,
                                    const IntegralGeodesicOptions& options,
                                    int32_t seed,
                                    const std::vector<double>& seed_distances);

// BruteForceSurfaceCentre sweeps from every vertex of the largest
// component: the test oracle. Cost n sweeps.
SurfaceCentre BruteForceSurfaceCentre(const MeshGraph& graph,
                                      DijkstraSolver& solver);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_INTEGRAL_GEODESIC_H_
