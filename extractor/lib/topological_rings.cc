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

namespace {

// ValidateRingInputs checks ExtractTopologicalRings' arguments.
absl::Status ValidateRingInputs(const MeshGraph& graph,
                                const std::vector<int32_t>& point_vertices,
                                const std::vector<double>& start_times,
                                const std::vector<int32_t>& centre_saddles,
                                const RingOptions& options) {
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
  return absl::OkStatus();
}

// Sweep: the multi-source wavefront propagation of 4.6.1-4.6.3, one front
// per topological point, merging fronts where they meet.
class Sweep {
 public:
  Sweep(const MeshGraph& graph, const std::vector<int32_t>& point_vertices,
        const std::vector<double>& start_times,
        const std::vector<int32_t>& centre_saddles, RingExtraction* out)
      : graph_(graph),
        out_(*out),
        num_points_(static_cast<int32_t>(point_vertices.size())),
        up_(num_points_),
        reached_by_(graph.num_vertices(), -1),
        settled_(graph.num_vertices(), 0),
        is_stop_(graph.num_vertices(), 0),
        live_(num_points_) {
    const int32_t n = graph.num_vertices();
    out_.owner.assign(n, -1);
    out_.level.assign(n, kUnreachable);
    out_.fronts.resize(num_points_);
    for (int32_t i = 0; i < num_points_; ++i) {
      out_.fronts[i].point = i;
      out_.fronts[i].birth = start_times[i];
      out_.fronts[i].points = {i};
    }
    component_ = num_points_ > 0 ? graph.component()[point_vertices[0]]
                                 : graph.largest_component();
    for (int32_t s : centre_saddles) {
      if (!is_stop_[s] && graph.component()[s] == component_) {
        is_stop_[s] = 1;
        ++remaining_saddles_;
      }
    }
    for (int32_t i = 0; i < num_points_; ++i) {
      const int32_t p = point_vertices[i];
      if (start_times[i] < out_.level[p]) {
        out_.level[p] = start_times[i];
        reached_by_[p] = i;
      }
      heap_.Push(start_times[i], p);
    }
    for (int32_t i = 0; i < num_points_; ++i)
      points_at_.push_back({point_vertices[i], i});
    std::sort(points_at_.begin(), points_at_.end());
  }

  // Run settles vertices in level order until one live front is left (live
  // wavefronts count points not yet started, 4.6.3), every centre saddle
  // is visited (with `stop_at_centre_saddles`), or the component is swept.
  void Run(bool stop_at_centre_saddles) {
    bool stop = live_ <= 1;
    while (!stop && !heap_.empty()) {
      const WavefrontHeap::Item top = heap_.Pop();
      const int32_t v = top.vertex;
      if (settled_[v] || top.key > out_.level[v]) continue;
      Settle(v);
      if (is_stop_[v] && --remaining_saddles_ == 0 && stop_at_centre_saddles) {
        out_.stopped_by_saddles = true;
        stop = true;
      }
      if (live_ <= 1) stop = true;
    }
  }

  int32_t component() const { return component_; }
  const std::vector<char>& settled() const { return settled_; }

 private:
  // Settle settles v: marks the points there that never start, merges the
  // fronts that meet at v into a new one, and relaxes v's edges.
  void Settle(int32_t v) {
    settled_[v] = 1;
    out_.final_level = out_.level[v];
    // Points at v other than the front that reached it never start: another
    // wavefront got there before their start time.
    for (auto it = std::lower_bound(points_at_.begin(), points_at_.end(),
                                    std::make_pair(v, -1));
         it != points_at_.end() && it->first == v; ++it) {
      if (it->second != reached_by_[v]) {
        out_.fronts[it->second].started = false;
        --live_;
      }
    }
    // Fronts touch across mesh edges (one_ring): a contact through an
    // unfolded shortcut is found one edge later, and the 1-ring scan costs
    // half as much.
    roots_.clear();
    roots_.push_back(static_cast<int32_t>(up_.Find(reached_by_[v])));
    for (int32_t w : graph_.one_ring(v)) {
      if (!settled_[w] || out_.owner[w] < 0) continue;
      const int32_t r = static_cast<int32_t>(up_.Find(out_.owner[w]));
      if (std::find(roots_.begin(), roots_.end(), r) == roots_.end())
        roots_.push_back(r);
    }
    const int32_t owner = roots_.size() > 1 ? Merge(v) : roots_.front();
    out_.owner[v] = owner;
    for (size_t k = 0; k < graph_.neighbors(v).size(); ++k) {
      const int32_t w = graph_.neighbors(v)[k];
      const double d = out_.level[v] + graph_.lengths(v)[k];
      if (!settled_[w] && d < out_.level[w]) {
        out_.level[w] = d;
        reached_by_[w] = owner;
        heap_.Push(d, w);
      }
    }
  }

  // Merge ends the fronts in roots_ at v (their death) and returns the new
  // front born there, which carries all their points.
  int32_t Merge(int32_t v) {
    std::vector<Front>& fronts = out_.fronts;
    std::sort(roots_.begin(), roots_.end());
    Front merged;
    merged.birth = out_.level[v];
    merged.children = roots_;
    const int32_t owner = static_cast<int32_t>(fronts.size());
    up_.Add();  // == owner
    for (int32_t r : roots_) {
      fronts[r].parent = owner;
      fronts[r].death = out_.level[v];
      up_.Link(r, owner);
      merged.points.insert(merged.points.end(), fronts[r].points.begin(),
                           fronts[r].points.end());
    }
    std::sort(merged.points.begin(), merged.points.end());
    fronts.push_back(std::move(merged));
    live_ -= static_cast<int>(roots_.size()) - 1;
    return owner;
  }

  const MeshGraph& graph_;
  RingExtraction& out_;
  const int32_t num_points_;
  // Fronts merged so far: the root of a front's set is the live front that
  // now carries its wavefront.
  DisjointSets up_;
  std::vector<int32_t> reached_by_;  // Front that set level[v].
  std::vector<char> settled_;
  std::vector<char> is_stop_;
  int remaining_saddles_ = 0;
  int32_t component_ = -1;
  WavefrontHeap heap_;
  std::vector<std::pair<int32_t, int32_t>> points_at_;  // (vertex, point)
  int live_;
  std::vector<int32_t> roots_;  // scratch of Settle
};

// AssignRegions makes the regions (FR is 0, then one per ring front) and
// gives each front, vertex and point its region.
void AssignRegions(const MeshGraph& graph,
                   const std::vector<int32_t>& point_vertices,
                   int32_t component, RingExtraction* out) {
  const std::vector<Front>& fronts = out->fronts;
  const int32_t n = graph.num_vertices();
  const int32_t num_points = static_cast<int32_t>(point_vertices.size());
  out->regions.push_back(Region{RegionKind::kFinal, -1, 0.0});
  const int32_t num_fronts = static_cast<int32_t>(fronts.size());
  out->front_region.assign(num_fronts, -1);
  std::vector<int32_t> ring_region(num_fronts, -1);
  for (int32_t f = 0; f < num_fronts; ++f) {
    if (!fronts[f].is_ring) continue;
    ring_region[f] = static_cast<int32_t>(out->regions.size());
    out->regions.push_back(Region{
        fronts[f].point >= 0 ? RegionKind::kProtrusion : RegionKind::kSegment,
        f, 0.0});
  }
  // Fronts are created after their children, so resolving from the last to
  // the first sees every parent resolved already.
  for (int32_t f = num_fronts - 1; f >= 0; --f) {
    if (ring_region[f] >= 0) {
      out->front_region[f] = ring_region[f];
    } else if (fronts[f].parent >= 0) {
      out->front_region[f] = out->front_region[fronts[f].parent];
    } else {
      out->front_region[f] = 0;
    }
  }
  out->vertex_region.assign(n, -1);
  const std::vector<double>& areas = graph.vertex_areas();
  for (int32_t v = 0; v < n; ++v) {
    int32_t r = -1;
    if (out->owner[v] >= 0) {
      r = out->front_region[out->owner[v]];
    } else if (graph.component()[v] == component) {
      r = 0;
    }
    out->vertex_region[v] = r;
    if (r >= 0) out->regions[r].area += areas[v];
  }
  out->point_region.assign(num_points, 0);
  for (int32_t i = 0; i < num_points; ++i) {
    const int32_t r = out->vertex_region[point_vertices[i]];
    out->point_region[i] = r < 0 ? 0 : r;
    // A point that never started lies in the region of the front that swept it.
    if (!fronts[i].started) out->front_region[i] = out->point_region[i];
  }
}

// FindRingVertices gives each ring front its vertices at the merge: those
// with a neighbour that was not yet settled when the front died (settled
// later, or never).
void FindRingVertices(const MeshGraph& graph, const std::vector<char>& settled,
                      RingExtraction* out) {
  std::vector<Front>& fronts = out->fronts;
  const int32_t n = graph.num_vertices();
  for (int32_t v = 0; v < n; ++v) {
    const int32_t f = out->owner[v];
    if (f < 0 || !fronts[f].is_ring) continue;
    for (int32_t w : graph.one_ring(v)) {
      if (out->owner[w] != f &&
          (!settled[w] || out->level[w] >= fronts[f].death)) {
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
        if (out->owner[v] >= 0 && &fronts[out->owner[v]] == &f) {
          f.ring_vertices.push_back(v);
          break;
        }
      }
    }
  }
}

}  // namespace

absl::StatusOr<RingExtraction> ExtractTopologicalRings(
    const MeshGraph& graph, const std::vector<int32_t>& point_vertices,
    const std::vector<double>& start_times,
    const std::vector<int32_t>& centre_saddles, const RingOptions& options) {
  if (absl::Status st = ValidateRingInputs(graph, point_vertices, start_times,
                                           centre_saddles, options);
      !st.ok()) {
    return st;
  }
  const int32_t num_points = static_cast<int32_t>(point_vertices.size());
  RingExtraction out;
  Sweep sweep(graph, point_vertices, start_times, centre_saddles, &out);
  sweep.Run(options.stop_at_centre_saddles);
  // Eq. 3 per dying front.
  for (Front& f : out.fronts) {
    if (f.parent < 0 || !f.started) continue;
    f.length = f.death - f.birth;
    f.is_ring = f.length > options.length_threshold;
  }
  AssignRegions(graph, point_vertices, sweep.component(), &out);
  FindRingVertices(graph, sweep.settled(), &out);
  int alive = 0;
  const int32_t num_fronts = static_cast<int32_t>(out.fronts.size());
  for (int32_t f = 0; f < num_fronts; ++f) {
    alive += out.fronts[f].parent < 0 && out.fronts[f].started &&
             (f >= num_points || sweep.settled()[point_vertices[f]]);
  }
  out.live_fronts_at_end = alive;
  return out;
}

}  // namespace tpr::extract
