// Topological Point Selection (4.4).
#include "extractor/lib/topological_points.h"

#include <algorithm>
#include <numeric>
#include <tuple>

#include "extractor/lib/disjoint_sets.h"

namespace tpr::extract {

std::vector<PersistentMaximum> PersistentMaxima(
    const MeshGraph& graph, const std::vector<double>& field,
    double min_persistence) {
  const int32_t n = graph.num_vertices();
  std::vector<int32_t> order;
  order.reserve(n);
  for (int32_t v = 0; v < n; ++v) {
    if (field[v] != kUnreachable) order.push_back(v);
  }
  // Decreasing field, ties by id: the order that defines "strictly lower".
  const auto higher = [&](int32_t a, int32_t b) {
    return std::tie(field[b], a) < std::tie(field[a], b);
  };
  std::sort(order.begin(), order.end(), higher);
  DisjointSets sets(n);
  std::vector<int32_t> top(n, -1);     // per root: the component's maximum
  std::vector<int32_t> lowest(n, -1);  // per root: its last vertex added
  std::vector<char> added(n, 0);
  std::vector<PersistentMaximum> out;
  for (int32_t v : order) {
    added[v] = 1;
    int64_t root = -1;
    for (int32_t w : graph.neighbors(v)) {
      if (!added[w] || w == v) continue;
      const int64_t r = sets.Find(w);
      if (root < 0) {
        root = r;
      } else if (r != root) {
        // Two components meet at v: the one with the lower maximum dies
        // here (the elder rule).
        int64_t hi = root, lo = r;
        if (higher(top[lo], top[hi])) std::swap(hi, lo);
        const double p = field[top[lo]] - field[v];
        if (p >= min_persistence) out.push_back({top[lo], v, p});
        const int32_t keep = top[hi];
        sets.Union(hi, lo);
        root = sets.Find(hi);
        top[root] = keep;
      }
    }
    if (root < 0) {
      top[v] = v;  // a new maximum
      root = v;
    } else {
      sets.Union(root, v);
      const int32_t keep = top[root];
      root = sets.Find(root);
      top[root] = keep;
    }
    lowest[root] = v;
  }
  // The highest maximum of each component never dies; its component's
  // lowest vertex is the last one added to it.
  for (int32_t v : order) {
    if (sets.Find(v) != v) continue;
    const double p = field[top[v]] - field[lowest[v]];
    if (p >= min_persistence) out.push_back({top[v], -1, p});
  }
  std::sort(out.begin(), out.end(),
            [](const PersistentMaximum& a, const PersistentMaximum& b) {
              return std::tie(b.persistence, a.vertex) <
                     std::tie(a.persistence, b.vertex);
            });
  return out;
}

CriticalPoints SimplifyByPersistence(const MeshGraph& graph,
                                     const CriticalPoints& set,
                                     double min_persistence) {
  CriticalPoints out;
  out.source = set.source;
  out.distances = set.distances;
  for (const PersistentMaximum& m :
       PersistentMaxima(graph, set.distances, min_persistence)) {
    out.maxima.push_back(m.vertex);
    if (m.saddle >= 0) out.saddles.push_back(m.saddle);
  }
  // The source is the field's minimum, never a maximum; a one-vertex
  // component's lone vertex would be (persistence 0), so drop it.
  out.maxima.erase(
      std::remove(out.maxima.begin(), out.maxima.end(), set.source),
      out.maxima.end());
  return out;
}

std::vector<TopologicalPoint> SelectTopologicalPoints(
    const MeshGraph& graph, DijkstraSolver& solver,
    const std::vector<CriticalPoints>& sets, TopologicalPointStats* stats) {
  TopologicalPointStats local;
  const int32_t n = graph.num_vertices();
  const int num_sources = static_cast<int>(sets.size());

  // Distance of every vertex to the nearest saddle of any source: the search
  // radius of a maximum m is this distance at m (graph distances are
  // symmetric), so one sweep serves every m.
  std::vector<int32_t> saddles;
  for (const CriticalPoints& cp : sets) {
    saddles.insert(saddles.end(), cp.saddles.begin(), cp.saddles.end());
  }
  std::sort(saddles.begin(), saddles.end());
  saddles.erase(std::unique(saddles.begin(), saddles.end()), saddles.end());
  std::vector<double> to_saddle(n, kUnreachable);
  if (!saddles.empty()) {
    to_saddle = solver.Run(saddles);
    ++local.sweeps;
    local.vertices_visited += static_cast<int64_t>(solver.order().size());
  }

  // Per vertex: bit mask of the sources that have a maximum there.
  std::vector<uint32_t> max_sources(n, 0);
  struct Candidate {
    double prominence;
    int32_t vertex;
  };
  std::vector<Candidate> candidates;
  for (int i = 0; i < num_sources && i < 32; ++i) {
    for (int32_t m : sets[i].maxima) {
      if (max_sources[m] == 0) candidates.push_back({to_saddle[m], m});
      max_sources[m] |= 1u << i;
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) {
              return std::tie(b.prominence, a.vertex) <
                     std::tie(a.prominence, b.vertex);
            });

  std::vector<char> visited(n, 0);
  std::vector<TopologicalPoint> points;
  for (const Candidate& c : candidates) {
    const int32_t m = c.vertex;
    if (visited[m]) continue;
    RunOptions run;
    run.max_distance = to_saddle[m];
    solver.Run(m, run);
    ++local.sweeps;
    local.vertices_visited += static_cast<int64_t>(solver.order().size());
    uint32_t voters = 0;
    TopologicalPoint p;
    p.radius = to_saddle[m];
    for (int32_t v : solver.order()) {
      if (max_sources[v] != 0 && !visited[v]) {
        voters |= max_sources[v];
        p.members.push_back(v);
      }
    }
    p.votes = __builtin_popcount(voters);
    if (2 * p.votes <= num_sources) {
      visited[m] = 1;
      continue;
    }
    p.vertex = p.members.front();
    for (int32_t v : p.members) {
      visited[v] = 1;
      if (std::tie(to_saddle[v], p.vertex) > std::tie(to_saddle[p.vertex], v))
        p.vertex = v;
    }
    std::sort(p.members.begin(), p.members.end());
    points.push_back(std::move(p));
  }
  if (stats != nullptr) *stats = local;
  return points;
}

}  // namespace tpr::extract
