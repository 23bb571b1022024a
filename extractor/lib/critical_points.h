// Critical Point Analysis (Tam & Lau 2007, 4.3, Table 1, Fig. 3): the Level
// Set Diagram [14] traced by a Dijkstra wavefront from one source, with the
// cycle-based proximity filter applied at every saddle candidate.
//
//   MeshGraph graph = MeshGraph::Build(mesh);  // once per mesh
//   absl::StatusOr<CriticalPoints> cp = AnalyzeCriticalPoints(
//       graph, graph.links(), source, CriticalPointOptions{});
#ifndef TPR_EXTRACTOR_LIB_CRITICAL_POINTS_H_
#define TPR_EXTRACTOR_LIB_CRITICAL_POINTS_H_

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "extractor/lib/geodesic.h"
#include "extractor/lib/mesh.h"
#include "extractor/lib/vertex_links.h"

namespace tpr::extract {

// CriticalPointOptions controls the filter of 4.3.
struct CriticalPointOptions {
  // A cycle of C(l_s)^+ is valid when it holds more than this many vertices
  // (4.3, "we choose n = 1"). Default 1.
  int cycle_min_vertices = 1;
  // How far "around v" the depth-first search on the Dijkstra heap goes, in
  // edges from v. The paper bounds the search by the wavefront near v
  // (n_v + n_e << n, Table 4) without a number. Within a genus-0 surface two
  // arcs of v's ring that are connected through unvisited vertices at all
  // are in the same front, so only the size test (> n vertices) needs room:
  // any radius >= n + 1 decides Table 1 identically for pockets of <= n
  // vertices; a larger radius only lets a front that is a long narrow chain
  // be counted whole. Must be >= cycle_min_vertices + 1. Default 6.
  int search_hops = 6;
};

// CriticalPoints are the minimum, saddles and maxima of one source (4.4:
// CriticalSet_s = Max u Saddle u Min).
struct CriticalPoints {
  int32_t source = -1;
  // Registered maxima, in order of registration (non-decreasing distance).
  std::vector<int32_t> maxima;
  // Registered saddles (Table 1, > 1 valid cycle), in order of registration.
  std::vector<int32_t> saddles;
  // The scalar field g_s: per vertex, its distance from the source
  // (kUnreachable off the source's component).
  std::vector<double> distances;
  // Bookkeeping for tests and the cost model of Table 4.
  int saddle_candidates = 0;           // lambda_s
  int candidates_one_valid_cycle = 0;  // Table 1, row "1"
  int candidates_no_valid_cycle = 0;   // Table 1, row "0" (became maxima)
  int64_t search_visits = 0;           // n_v + n_e summed over candidates
};

// AnalyzeCriticalPoints traces the wavefront from `source` (Dijkstra over
// `graph`) and applies Table 1 at each saddle candidate: a vertex is a
// saddle candidate when, as it is settled, the already-settled vertices of
// its ring form more than one arc (the wavefront meets itself at v). Its
// C(l_s)^+ near v, the unvisited vertices adjacent to the front (those in
// the heap), is searched from v's unvisited neighbours through heap vertices
// up to options.search_hops edges from v and split into cycles by
// connectivity; cycles with > cycle_min_vertices vertices are valid. > 1
// valid: saddle; 1: no critical point, the invalid cycles of C(l_s)^+
// disallowed (the paper disallows all of C(l_s)^+; see the .cc for why the
// valid cycle is spared); 0: v becomes a maximum, C(l_s)^+ disallowed. A vertex
// all of whose neighbours are settled before it is a maximum unless disallowed.
// Disallowed vertices never become critical points. Returns INVALID_ARGUMENT
// when source is out of range, links and graph disagree in size, or the options
// are out of range. Cost: one Dijkstra sweep plus O(lambda_s * search_hops^2).
// Thread-safe (no shared state).
absl::StatusOr<CriticalPoints> AnalyzeCriticalPoints(
    const MeshGraph& graph, const VertexLinks& links, int32_t source,
    const CriticalPointOptions& options);

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_CRITICAL_POINTS_H_
