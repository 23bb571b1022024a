// Topological Ring Extraction (4.6). Our own multi-source Dijkstra rather
// than DijkstraSolver: merges must be detected at the moment a vertex is
// settled, with the fronts of its settled neighbours at that moment.
#include "extractor/lib/topological_rings.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "extractor/lib/disjoint_sets.h"
#include "extractor/lib/wavefront_heap.h"

namespace tpr::extract {

std::vector<double> RingStartTimes(const std::vector<double>& point_g,
                                   double g_min, double g_max, double max_g_o) {
  std::vector<double> start(point_g.size(), 0.0);
  const double span = g_max - g_min;
  if (!(span > 0.0)) return start;
  for (size_t i = 0; i < point_g.size(); ++i) {
    const double t = max_g_o * (g_max - point_g[i]) / span;  // Eq. 1
    start[i] = std::clamp(t, 0.0, max_g_o);
  }
  return start;
}

absl::StatusOr<RingExtraction> ExtractTopologicalRings(
    const MeshGraph& graph, const std::vector<int32_t>& point_vertices,
    const std::vector<double>& start_times,
    const std::vector<int32_t>& centre_saddles, const RingOptions& options) {
  const int32_t n = graph.num_vertices();
  const int32_t num_points = static_cast<int32_t>(point_vertices.size());
  if (start_times.size() != point_vertices.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("rings: ", point_vertices.size(), " points but ",
                     start_times.size(), " start times"));
  }
  for (int32_t i = 0; i < num_points; ++i) {
    if (point_vertices[i] < 0 || point_vertices[i] >= n) {
      return absl::InvalidArgumentError(
          absl::StrCat("rings: point ", i, " has vertex ", point_vertices[i],
                       " out of range"));
    }
    if (!std::isfinite(start_times[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("rings: start time of point ", i, " is not finite"));
    }
  }
  for (int32_t s : centre_saddles) {
    if (s < 0 || s >= n) {
      return absl::InvalidArgumentError(
          absl::StrCat("rings: saddle vertex ", s, " out of range"));
    }
  }
  if (!(options.length_threshold >= 0.0)) {
    return absl::InvalidArgumentError("rings: length_threshold must be >= 0");
  }

  RingExtraction out;
  out.owner.assign(n, -1);
  out.level.assign(n, kUnreachable);
  std::vector<Front>& fronts = out.fronts;
  fronts.resize(num_points);
  // Fronts merged so far: the root of a front's set is the live front that
  // now carries its wavefront.
  DisjointSets up(num_points);
  for (int32_t i = 0; i < num_points; ++i) {
    fronts[i].point = i;
    fronts[i].birth = start_times[i];
    fronts[i].points = {i};
  }
  const int32_t component = num_points > 0
                                ? graph.component()[point_vertices[0]]
                                : graph.largest_component();

  std::vector<int32_t> reached_by(n, -1);  // Front that set level[v].
  std::vector<char> settled(n, 0);
  std::vector<char> is_stop(n, 0);
  int remaining_saddles = 0;
  for (int32_t s : centre_saddles) {
    if (!is_stop[s] && graph.component()[s] == component) {
      is_stop[s] = 1;
      ++remaining_saddles;
    }
  }
  std::vector<double>& level = out.level;
  WavefrontHeap heap;
  for (int32_t i = 0; i < num_points; ++i) {
    const int32_t p = point_vertices[i];
    if (start_times[i] < level[p]) {
      level[p] = start_times[i];
      reached_by[p] = i;
    }
    heap.Push(start_times[i], p);
  }
  std::vector<std::pair<int32_t, int32_t>> points_at;  // (vertex, point)
  for (int32_t i = 0; i < num_points; ++i)
    points_at.push_back({point_vertices[i], i});
  std::sort(points_at.begin(), points_at.end());
  // Live wavefronts, counting points not yet started: the algorithm ends
  // when all have merged into one (4.6.3).
  int live = num_points;
  std::vector<int32_t> roots;
  bool stop = live <= 1;
  while (!stop && !heap.empty()) {
    const WavefrontHeap::Item top = heap.Pop();
    const int32_t v = top.vertex;
    if (settled[v] || top.key > level[v]) continue;
    settled[v] = 1;
    out.final_level = level[v];
    // Points at v other than the front that reached it never start: another
    // wavefront got there before their start time.
    for (auto it = std::lower_bound(points_at.begin(), points_at.end(),
                                    std::make_pair(v, -1));
         it != points_at.end() && it->first == v; ++it) {
      if (it->second != reached_by[v]) {
        fronts[it->second].started = false;
        --live;
      }
    }
    // Fronts touch across mesh edges (one_ring): a contact through an
    // unfolded shortcut is found one edge later, and the 1-ring scan costs
    // half as much.
    roots.clear();
    roots.push_back(static_cast<int32_t>(up.Find(reached_by[v])));
    for (int32_t w : graph.one_ring(v)) {
      if (!settled[w] || out.owner[w] < 0) continue;
      const int32_t r = static_cast<int32_t>(up.Find(out.owner[w]));
      if (std::find(roots.begin(), roots.end(), r) == roots.end())
        roots.push_back(r);
    }
    int32_t owner = roots.front();
    if (roots.size() > 1) {
      std::sort(roots.begin(), roots.end());
      Front merged;
      merged.birth = level[v];
      merged.children = roots;
      owner = static_cast<int32_t>(fronts.size());
      up.Add();  // == owner
      for (int32_t r : roots) {
        fronts[r].parent = owner;
        fronts[r].death = level[v];
        up.Link(r, owner);
        merged.points.insert(merged.points.end(), fronts[r].points.begin(),
                             fronts[r].points.end());
      }
      std::sort(merged.points.begin(), merged.points.end());
      fronts.push_back(std::move(merged));
      live -= static_cast<int>(roots.size()) - 1;
    }
    out.owner[v] = owner;
    for (size_t k = 0; k < graph.neighbors(v).size(); ++k) {
      const int32_t w = graph.neighbors(v)[k];
      const double d = level[v] + graph.lengths(v)[k];
      if (!settled[w] && d < level[w]) {
        level[w] = d;
        reached_by[w] = owner;
        heap.Push(d, w);
      }
    }
    if (is_stop[v] && --remaining_saddles == 0 &&
        options.stop_at_centre_saddles) {
      out.stopped_by_saddles = true;
      stop = true;
    }
    if (live <= 1) stop = true;
  }
  // Eq. 3 per dying front.
  for (Front& f : fronts) {
    if (f.parent < 0 || !f.started) continue;
    f.length = f.death - f.birth;
    f.is_ring = f.length > options.length_threshold;
  }

  // Regions: FR is 0, then one per ring front.
  out.regions.push_back(Region{RegionKind::kFinal, -1, 0.0});
  const int32_t num_fronts = static_cast<int32_t>(fronts.size());
  out.front_region.assign(num_fronts, -1);
  std::vector<int32_t> ring_region(num_fronts, -1);
  for (int32_t f = 0; f < num_fronts; ++f) {
    if (!fronts[f].is_ring) continue;
    ring_region[f] = static_cast<int32_t>(out.regions.size());
    out.regions.push_back(Region{
        fronts[f].point >= 0 ? RegionKind::kProtrusion : RegionKind::kSegment,
        f, 0.0});
  }
  // Fronts are created after their children, so resolving from the last to
  // the first sees every parent resolved already.
  for (int32_t f = num_fronts - 1; f >= 0; --f) {
    if (ring_region[f] >= 0) {
      out.front_region[f] = ring_region[f];
    } else if (fronts[f].parent >= 0) {
      out.front_region[f] = out.front_region[fronts[f].parent];
    } else {
      out.front_region[f] = 0;
    }
  }
  out.vertex_region.assign(n, -1);
  const std::vector<double>& areas = graph.vertex_areas();
  for (int32_t v = 0; v < n; ++v) {
    int32_t r = -1;
    if (out.owner[v] >= 0) {
      r = out.front_region[out.owner[v]];
    } else if (graph.component()[v] == component) {
      r = 0;
    }
    out.vertex_region[v] = r;
    if (r >= 0) out.regions[r].area += areas[v];
  }
  out.point_region.assign(num_points, 0);
  for (int32_t i = 0; i < num_points; ++i) {
    const int32_t r = out.vertex_region[point_vertices[i]];
    out.point_region[i] = r < 0 ? 0 : r;
    // A point that never started lies in the region of the front that swept it.
    if (!fronts[i].started) out.front_region[i] = out.point_region[i];
  }

  // Ring vertices: the front's vertices with a neighbour that was not yet
  // settled when the front died (settled later, or never).
  for (int32_t v = 0; v < n; ++v) {
    const int32_t f = out.owner[v];
    if (f < 0 || !fronts[f].is_ring) continue;
    for (int32_t w : graph.one_ring(v)) {
      if (out.owner[w] != f && (!settled[w] || level[w] >= fronts[f].death)) {
        fronts[f].ring_vertices.push_back(v);
        break;
      }
    }
  }
  for (Front& f : fronts) {
    if (f.is_ring && f.ring_vertices.empty()) {
      // A front that swept a whole closed piece has no border; keep its
      // first vertex so that the ring still has a place (not seen on
      // connected inputs, where the merge vertex is always outside).
      for (int32_t v = 0; v < n; ++v) {
        if (out.owner[v] >= 0 && &fronts[out.owner[v]] == &f) {
          f.ring_vertices.push_back(v);
          break;
        }
      }
    }
  }
  int alive = 0;
  for (int32_t f = 0; f < num_fronts; ++f) {
    alive += fronts[f].parent < 0 && fronts[f].started &&
             (f >= num_points || settled[point_vertices[f]]);
  }
  out.live_fronts_at_end = alive;
  return out;
}

}  // namespace tpr::extract
