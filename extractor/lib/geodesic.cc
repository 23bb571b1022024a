#include "extractor/lib/geodesic.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace tpr::extract {
namespace {

// An undirected arc u < v with its length, before compression into rows.
struct Arc {
  int32_t u;
  int32_t v;
  double length;
};

// UnfoldedLength returns the length of the straight segment from c to d with
// triangles (a, b, c) and (a, b, d) unfolded into one plane about edge (a,
// b), or a negative value when that segment does not cross the open edge
// (then the straight line leaves the two triangles and is no surface path).
// The unfolded segment is a genuine path on the surface, so adding it keeps
// Dijkstra an upper bound of the geodesic.
double UnfoldedLength(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                      const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  const Eigen::Vector3d ab = b - a;
  const double len = ab.norm();
  if (!(len > 0.0)) return -1.0;
  const Eigen::Vector3d axis = ab / len;
  const Eigen::Vector3d ac = c - a;
  const Eigen::Vector3d ad = d - a;
  const double xc = ac.dot(axis);
  const double yc = (ac - xc * axis).norm();
  const double xd = ad.dot(axis);
  const double yd = (ad - xd * axis).norm();  // on the other side: -yd
  if (!(yc > 0.0) || !(yd > 0.0)) return -1.0;
  const double x_cross = xc + (xd - xc) * yc / (yc + yd);
  // Strictly inside, with a small margin: a path through a vertex is
  // already covered by the two edge paths.
  const double margin = 1e-9 * len;
  if (x_cross <= margin || x_cross >= len - margin) return -1.0;
  const double dx = xd - xc;
  const double dy = yc + yd;
  // Not std::hypot: its overflow care is not needed here and is slow.
  return std::sqrt(dx * dx + dy * dy);
}

// InsertionSort sorts [first, last): the ranges here (one vertex's edges)
// hold about 6 to 12 entries, where it beats std::sort.
template <typename T, typename Less>
void InsertionSort(T* first, T* last, Less less) {
  for (T* i = first + (first == last ? 0 : 1); i < last; ++i) {
    T value = *i;
    T* j = i;
    while (j > first && less(value, *(j - 1))) {
      *j = *(j - 1);
      --j;
    }
    *j = value;
  }
}

}  // namespace

MeshGraph MeshGraph::Build(const Mesh& mesh, const GeodesicOptions& options) {
  MeshGraph g;
  g.mesh_ = &mesh;
  const int32_t n = static_cast<int32_t>(mesh.positions.size());
  const auto& p = mesh.positions;

  g.vertex_areas_.assign(n, 0.0);
  for (const auto& t : mesh.triangles) {
    assert(t[0] >= 0 && t[0] < n && t[1] >= 0 && t[1] < n && t[2] >= 0 &&
           t[2] < n);
    const double area =
        0.5 * (p[t[1]] - p[t[0]]).cross(p[t[2]] - p[t[0]]).norm();
    for (int k = 0; k < 3; ++k) g.vertex_areas_[t[k]] += area / 3.0;
  }
  g.total_area_ = 0.0;
  for (double a : g.vertex_areas_) g.total_area_ += a;

  // The edges and their opposite vertices come from the 1-rings: each link
  // edge (x, y) of v (triangle (v, x, y)) is a side of edge (v, x) with
  // opposite vertex y and a side of edge (v, y) with opposite x, sides
  // touching v twice (degenerate) left out. Every edge side of the mesh is
  // counted once, at its lower vertex, in (lo, hi) order: no sort of the
  // 3f sides, which cost as much as the rest of Build.
  g.links_ = VertexLinks::Build(mesh);
  const VertexLinks& links = g.links_;
  std::vector<Arc> arcs;
  // About 3f/2 edges, and as many shortcuts when unfolding.
  arcs.reserve(3 * mesh.triangles.size() / 2 *
                   (options.unfold_opposite_edges ? 2 : 1) +
               16);
  for (int32_t a = 0; a < n; ++a) {
    for (const int32_t* nb = links.neighbors_begin(a);
         nb != links.neighbors_end(a); ++nb) {
      const int32_t b = *nb;
      if (b <= a) continue;
      arcs.push_back({a, b, (p[a] - p[b]).norm()});
      if (!options.unfold_opposite_edges) continue;
      // Only manifold interior edges (exactly two triangles) have a well
      // defined unfolding.
      int sides = 0;
      int32_t opposite[2] = {-1, -1};
      for (const int32_t* e = links.link_begin(a); e != links.link_end(a);
           e += 2) {
        for (int end = 0; end < 2; ++end) {
          if (e[end] != b) continue;
          if (sides < 2) opposite[sides] = e[1 - end];
          ++sides;
        }
      }
      if (sides != 2) continue;
      const int32_t c = std::min(opposite[0], opposite[1]);
      const int32_t d = std::max(opposite[0], opposite[1]);
      if (c != d) {
        const double len = UnfoldedLength(p[a], p[b], p[c], p[d]);
        if (len > 0.0) arcs.push_back({c, d, len});
      }
    }
  }

  // Rows with possible duplicates (a shortcut may repeat a mesh edge or
  // another shortcut), then sorted and compacted per row keeping the
  // shortest length per neighbour.
  std::vector<int64_t> raw(static_cast<size_t>(n) + 1, 0);
  for (const Arc& e : arcs) {
    ++raw[e.u + 1];
    ++raw[e.v + 1];
  }
  for (int32_t v = 0; v < n; ++v) raw[v + 1] += raw[v];
  std::vector<std::pair<int32_t, double>> row_entries(arcs.size() * 2);
  {
    std::vector<int64_t> fill(raw.begin(), raw.end() - 1);
    for (const Arc& e : arcs) {
      row_entries[fill[e.u]++] = {e.v, e.length};
      row_entries[fill[e.v]++] = {e.u, e.length};
    }
  }
  auto entry_less = [](const std::pair<int32_t, double>& x,
                       const std::pair<int32_t, double>& y) {
    return x.first != y.first ? x.first < y.first : x.second < y.second;
  };
  g.offsets_.assign(static_cast<size_t>(n) + 1, 0);
  g.targets_.clear();
  g.lengths_.clear();
  g.targets_.reserve(row_entries.size());
  g.lengths_.reserve(row_entries.size());
  for (int32_t v = 0; v < n; ++v) {
    auto* first = row_entries.data() + raw[v];
    auto* last = row_entries.data() + raw[v + 1];
    InsertionSort(first, last, entry_less);
    for (auto* it = first; it != last; ++it) {
      if (it != first && it->first == (it - 1)->first) continue;
      g.targets_.push_back(it->first);
      g.lengths_.push_back(it->second);
    }
    g.offsets_[v + 1] = static_cast<int64_t>(g.targets_.size());
  }

  // Components by breadth-first search over the rows.
  g.component_.assign(n, -1);
  g.num_components_ = 0;
  std::vector<int32_t> queue;
  queue.reserve(n);
  for (int32_t s = 0; s < n; ++s) {
    if (g.component_[s] >= 0) continue;
    const int32_t id = g.num_components_++;
    double area = 0.0;
    queue.clear();
    queue.push_back(s);
    g.component_[s] = id;
    for (size_t h = 0; h < queue.size(); ++h) {
      const int32_t v = queue[h];
      area += g.vertex_areas_[v];
      for (int64_t k = g.offsets_[v]; k < g.offsets_[v + 1]; ++k) {
        const int32_t u = g.targets_[k];
        if (g.component_[u] < 0) {
          g.component_[u] = id;
          queue.push_back(u);
        }
      }
    }
    g.component_areas_.push_back(area);
  }
  return g;
}

absl::StatusOr<MeshGraph> MeshGraph::Create(const Mesh& mesh,
                                            const GeodesicOptions& options) {
  const size_t n = mesh.positions.size();
  if (n == 0) return absl::InvalidArgumentError("mesh has no vertices");
  if (n > static_cast<size_t>(std::numeric_limits<int32_t>::max() / 2)) {
    return absl::InvalidArgumentError(
        absl::StrCat("mesh has too many vertices for 32-bit ids: ", n));
  }
  for (size_t v = 0; v < n; ++v) {
    if (!mesh.positions[v].allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("vertex ", v, " has a non-finite coordinate"));
    }
  }
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int32_t i = mesh.triangles[f][k];
      if (i < 0 || static_cast<size_t>(i) >= n) {
        return absl::InvalidArgumentError(
            absl::StrCat("triangle ", f, " refers to vertex ", i,
                         ", out of range [0, ", n, ")"));
      }
    }
  }
  return Build(mesh, options);
}

int32_t MeshGraph::largest_component() const {
  int32_t best = -1;
  for (int32_t c = 0; c < num_components_; ++c) {
    if (best < 0 || component_areas_[c] > component_areas_[best]) best = c;
  }
  return best;
}

DijkstraSolver::DijkstraSolver(const MeshGraph& graph) : graph_(&graph) {
  const int32_t n = graph.num_vertices();
  dist_.assign(n, kUnreachable);
  source_.assign(n, -1);
  parent_.assign(n, -1);
  order_.reserve(n);
  touched_.reserve(n);
  // The heap's buckets grow during the first sweep and keep their capacity.
}

void DijkstraSolver::Reset() {
  for (int32_t v : reset_from_order_ ? order_ : touched_) {
    dist_[v] = kUnreachable;
    source_[v] = -1;
    parent_[v] = -1;
  }
  touched_.clear();
  order_.clear();
  reset_from_order_ = false;
  for (auto& b : buckets_) b.clear();
  nonempty_ = 0;
  heap_size_ = 0;
  last_key_ = 0;
}

namespace {

// OrderedBits maps a double to an unsigned integer of the same order (the
// IEEE sign-magnitude pattern with negatives flipped), so the radix heap
// can bucket by the highest differing bit. Exactly invertible.
inline uint64_t OrderedBits(double x) {
  uint64_t u;
  std::memcpy(&u, &x, sizeof u);
  return (u >> 63) ? ~u : (u | (uint64_t{1} << 63));
}

inline double FromOrderedBits(uint64_t u) {
  u = (u >> 63) ? (u & ~(uint64_t{1} << 63)) : ~u;
  double x;
  std::memcpy(&x, &u, sizeof x);
  return x;
}

inline int BucketOf(uint64_t key, uint64_t last) {
  return key == last ? 0 : 64 - __builtin_clzll(key ^ last);
}

}  // namespace

void DijkstraSolver::Push(double key, int32_t vertex) {
  const uint64_t k = OrderedBits(key);
  assert(k >= last_key_);  // monotone: Dijkstra never pushes below the front
  const int b = BucketOf(k, last_key_);
  buckets_[b].push_back({k, vertex});
  if (b > 0) nonempty_ |= uint64_t{1} << (b - 1);
  ++heap_size_;
}

int32_t DijkstraSolver::Pop(double* key) {
  if (buckets_[0].empty()) {
    assert(nonempty_ != 0);
    const int i = __builtin_ctzll(nonempty_) + 1;
    // The new front is the smallest key of the first non-empty bucket; every
    // entry of that bucket then falls into a lower one.
    uint64_t front = buckets_[i][0].key;
    for (const HeapEntry& e : buckets_[i]) front = std::min(front, e.key);
    last_key_ = front;
    for (const HeapEntry& e : buckets_[i]) {
      const int b = BucketOf(e.key, last_key_);
      buckets_[b].push_back(e);
      if (b > 0) nonempty_ |= uint64_t{1} << (b - 1);
    }
    buckets_[i].clear();
    nonempty_ &= ~(uint64_t{1} << (i - 1));
  }
  const HeapEntry e = buckets_[0].back();
  buckets_[0].pop_back();
  --heap_size_;
  *key = FromOrderedBits(e.key);
  return e.vertex;
}

const std::vector<double>& DijkstraSolver::Run(int32_t source,
                                               const RunOptions& run) {
  const int32_t sources[1] = {source};
  return Run(absl::MakeConstSpan(sources, 1), {}, run);
}

const std::vector<double>& DijkstraSolver::Run(
    absl::Span<const int32_t> sources, absl::Span<const double> initial_values,
    const RunOptions& run) {
  assert(initial_values.empty() || initial_values.size() == sources.size());
  Reset();
  const MeshGraph& g = *graph_;
  for (size_t i = 0; i < sources.size(); ++i) {
    const int32_t v = sources[i];
    assert(v >= 0 && v < g.num_vertices());
    const double t = initial_values.empty() ? 0.0 : initial_values[i];
    assert(std::isfinite(t));
    if (t < dist_[v]) {
      if (dist_[v] == kUnreachable) touched_.push_back(v);
      dist_[v] = t;
      source_[v] = static_cast<int32_t>(i);
      Push(t, v);
    }
  }
  const double max_distance = run.max_distance;
  // Unbounded, every vertex touched is settled and so in order_, which
  // Reset then walks: no bookkeeping of first reaches in the inner loop.
  const bool bounded = max_distance != kUnreachable;
  reset_from_order_ = !bounded;
  double* const dist = dist_.data();
  int32_t* const parent = parent_.data();
  bool stopped_early = false;
  // No settled flags: a vertex's heap entries carry strictly decreasing
  // keys (pushed only on improvement) and lengths are non-negative, so the
  // entry whose key equals dist_ is popped exactly once, and a relaxation
  // can never improve a settled vertex. The wavefront label is copied from
  // the parent when a vertex settles rather than on every relaxation: one
  // scattered write less in the inner loop.
  while (!HeapEmpty()) {
    double key;
    const int32_t v = Pop(&key);
    if (key > dist[v]) continue;  // stale entry
    if (key > max_distance) {
      stopped_early = true;
      break;
    }
    if (parent[v] >= 0) source_[v] = source_[parent[v]];
    order_.push_back(v);
    const absl::Span<const int32_t> nbrs = g.neighbors(v);
    const absl::Span<const double> lens = g.lengths(v);
    for (size_t k = 0; k < nbrs.size(); ++k) {
      const int32_t u = nbrs[k];
      const double nd = key + lens[k];
      const double old = dist[u];
      if (nd < old) {
        if (bounded && old == kUnreachable) touched_.push_back(u);
        dist[u] = nd;
        parent[u] = v;
        Push(nd, u);
      }
    }
  }
  if (stopped_early) {
    // Tentative distances beyond the bound are not results: report them as
    // unreached, keeping touched_ so the next Reset still clears them. Every
    // vertex left unsettled has a tentative distance above the bound.
    for (int32_t v : touched_) {
      if (dist_[v] > max_distance) {
        dist_[v] = kUnreachable;
        source_[v] = -1;
        parent_[v] = -1;
      }
    }
  }
  return dist_;
}

}  // namespace tpr::extract
