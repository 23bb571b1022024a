// Critical Point Analysis (4.3). The wavefront is traced by our own Dijkstra
// rather than DijkstraSolver because Table 1 needs the heap and the settled
// state at the moment a saddle candidate is settled, which the solver does
// not expose mid-sweep.
#include "extractor/lib/critical_points.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "extractor/lib/wavefront_heap.h"

namespace tpr::extract {

absl::StatusOr<CriticalPoints> AnalyzeCriticalPoints(
    const MeshGraph& graph, const VertexLinks& links, int32_t source,
    const CriticalPointOptions& options) {
  const int32_t n = graph.num_vertices();
  if (links.num_vertices() != n) {
    return absl::InvalidArgumentError(
        absl::StrCat("critical points: links have ", links.num_vertices(),
                     " vertices, graph has ", n));
  }
  if (source < 0 || source >= n) {
    return absl::InvalidArgumentError(absl::StrCat(
        "critical points: source ", source, " out of range [0, ", n, ")"));
  }
  if (options.cycle_min_vertices < 0) {
    return absl::InvalidArgumentError(
        "critical points: cycle_min_vertices must be >= 0");
  }
  if (options.search_hops < options.cycle_min_vertices + 1) {
    return absl::InvalidArgumentError(
        "critical points: search_hops must be >= cycle_min_vertices + 1");
  }

  CriticalPoints out;
  out.source = source;
  out.distances.assign(n, kUnreachable);
  std::vector<char> settled(n, 0);
  std::vector<char> disallowed(n, 0);
  // Scratch of the bounded search, valid where stamp == candidate number.
  std::vector<int32_t> stamp(n, -1);
  std::vector<int32_t> cycle_of(n, -1);
  std::vector<int32_t> depth(n, 0);
  std::vector<int32_t> queue;
  std::vector<int32_t> cycle_sizes;

  std::vector<double>& dist = out.distances;
  WavefrontHeap heap;
  dist[source] = 0.0;
  heap.Push(0.0, source);
  int32_t candidate_id = 0;
  while (!heap.empty()) {
    const WavefrontHeap::Item top = heap.Pop();
    const int32_t v = top.vertex;
    if (settled[v] || top.key > dist[v]) continue;
    settled[v] = 1;
    auto nbrs = graph.neighbors(v);
    auto lens = graph.lengths(v);
    for (size_t k = 0; k < nbrs.size(); ++k) {
      const int32_t w = nbrs[k];
      const double d = dist[v] + lens[k];
      if (!settled[w] && d < dist[w]) {
        dist[w] = d;
        heap.Push(d, w);
      }
    }
    if (v == source || disallowed[v]) continue;

    // Arcs of settled vertices in v's ring: on a closed ring (a cycle) the
    // number of arcs of a proper subset S is |S| minus the link edges inside
    // S; on a boundary ring (a path) the same formula holds.
    const int32_t deg = links.degree(v);
    int32_t settled_count = 0;
    for (const int32_t* p = links.neighbors_begin(v);
         p != links.neighbors_end(v); ++p) {
      settled_count += settled[*p];
    }
    if (deg > 0 && settled_count == deg) {
      out.maxima.push_back(v);  // Every neighbour is lower: a maximum.
      continue;
    }
    int32_t settled_edges = 0;
    for (const int32_t* p = links.link_begin(v); p != links.link_end(v);
         p += 2) {
      settled_edges += settled[p[0]] & settled[p[1]];
    }
    if (settled_count - settled_edges < 2)
      continue;  // Front does not meet itself.

    // Saddle candidate: C(l_s)^+ around v by a search on the heap vertices
    // (unsettled with a finite tentative distance), split into cycles by
    // connectivity; each unvisited arc of v's ring seeds the search.
    ++out.saddle_candidates;
    const int32_t id = candidate_id++;
    cycle_sizes.clear();
    queue.clear();
    for (const int32_t* p = links.neighbors_begin(v);
         p != links.neighbors_end(v); ++p) {
      const int32_t seed = *p;
      if (settled[seed] || stamp[seed] == id) continue;
      const int32_t cycle = static_cast<int32_t>(cycle_sizes.size());
      cycle_sizes.push_back(0);
      stamp[seed] = id;
      cycle_of[seed] = cycle;
      depth[seed] = 1;
      size_t head = queue.size();
      queue.push_back(seed);
      while (head < queue.size()) {
        const int32_t u = queue[head++];
        ++cycle_sizes[cycle];
        ++out.search_visits;
        if (depth[u] >= options.search_hops) continue;
        for (const int32_t* q = links.neighbors_begin(u);
             q != links.neighbors_end(u); ++q) {
          const int32_t w = *q;
          ++out.search_visits;
          if (settled[w] || dist[w] == kUnreachable || stamp[w] == id) continue;
          stamp[w] = id;
          cycle_of[w] = cycle;
          depth[w] = depth[u] + 1;
          queue.push_back(w);
        }
      }
    }
    int valid = 0;
    for (int32_t s : cycle_sizes) valid += s > options.cycle_min_vertices;
    if (valid > 1) {
      out.saddles.push_back(v);  // Table 1, case A: branching.
      continue;
    }
    // Table 1, cases B and C: disallow C(l_s)^+. In case C every cycle is
    // invalid and all of C(l_s)^+ is disallowed, as written. In case B we
    // disallow the invalid cycles only (the pocket vertices that would
    // otherwise surface as extraneous maxima, Fig. 3 B), not the one valid
    // cycle: that cycle is the front that goes on, and near a protrusion tip
    // it is the small loop about to close there; disallowing it loses the
    // tip's maximum (seen on a 6-arm star: the arm opposite the source had
    // no maximum). tests/extractor/critical_points_test.cc covers both.
    for (int32_t u : queue) {
      if (valid == 0 ||
          cycle_sizes[cycle_of[u]] <= options.cycle_min_vertices) {
        disallowed[u] = 1;
      }
    }
    if (valid == 1) {
      ++out.candidates_one_valid_cycle;
    } else {
      ++out.candidates_no_valid_cycle;
      out.maxima.push_back(v);
    }
  }
  return out;
}

}  // namespace tpr::extract
