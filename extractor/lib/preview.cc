#include "extractor/lib/preview.h"

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <queue>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"

namespace tpr::extract {
namespace {

// Compact returns `mesh` without unreferenced vertices, the others in
// their order.
Mesh Compact(const Mesh& mesh) {
  std::vector<int32_t> remap(mesh.positions.size(), -1);
  Mesh out;
  out.triangles.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    for (int32_t v : t) remap[v] = 0;
  }
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    if (remap[v] < 0) continue;
    remap[v] = static_cast<int32_t>(out.positions.size());
    out.positions.push_back(mesh.positions[v]);
  }
  for (const auto& t : mesh.triangles) {
    out.triangles.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
  }
  return out;
}

// Quadric error metrics (Garland & Heckbert 1997): each vertex carries the
// area-weighted sum of its triangles' plane quadrics; a halfedge collapse
// u -> v costs the summed quadric of u and v evaluated at v, and moves no
// vertex. One heap entry per vertex holds its cheapest target (by cost
// alone); legality is checked when the entry comes out, so the few
// collapses that would break the surface cost a re-scan of one vertex, not
// a check of every candidate every time (OpenMesh's DecimaterT checks
// every candidate: about 240 ms at 10k vertices, docs/benchmarks.md).
struct Quadric {
  // aa ab ac ad bb bc bd cc cd dd of the symmetric 4 x 4 matrix.
  std::array<double, 10> q{};

  void AddPlane(const Eigen::Vector3d& n, double d, double w) {
    const double a = n.x(), b = n.y(), c = n.z();
    const std::array<double, 10> p = {a * a, a * b, a * c, a * d, b * b,
                                      b * c, b * d, c * c, c * d, d * d};
    for (int i = 0; i < 10; ++i) q[i] += w * p[i];
  }
  void Add(const Quadric& o) {
    for (int i = 0; i < 10; ++i) q[i] += o.q[i];
  }
  // x^T Q x for x = (p, 1), with `o` added.
  double Eval(const Quadric& o, const Eigen::Vector3d& p) const {
    std::array<double, 10> s;
    for (int i = 0; i < 10; ++i) s[i] = q[i] + o.q[i];
    const double x = p.x(), y = p.y(), z = p.z();
    return s[0] * x * x + 2 * s[1] * x * y + 2 * s[2] * x * z + 2 * s[3] * x +
           s[4] * y * y + 2 * s[5] * y * z + 2 * s[6] * y + s[7] * z * z +
           2 * s[8] * z + s[9];
  }
};

Eigen::Vector3d Cross(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return {a.y() * b.z() - a.z() * b.y(), a.z() * b.x() - a.x() * b.z(),
          a.x() * b.y() - a.y() * b.x()};
}

class Decimator {
 public:
  explicit Decimator(const Mesh& mesh);
  // Collapses until at most `max_faces` triangles are left or no collapse
  // is legal; returns the triangles left.
  size_t Run(size_t max_faces);
  Mesh Result() const;

 private:
  struct Entry {
    double cost;
    int32_t from, to;
    uint32_t stamp;
    // Min-heap on (cost, from, to): deterministic order on ties.
    bool operator<(const Entry& o) const {
      if (cost != o.cost) return cost > o.cost;
      if (from != o.from) return from > o.from;
      return to > o.to;
    }
  };

  // The live faces of v (dead ones dropped from its list).
  const std::vector<int32_t>& Faces(int32_t v);
  // Pushes v's cheapest target; with `legal`, the cheapest legal one.
  void Schedule(int32_t v, bool legal);
  // Makes (target, cost) v's one valid heap entry (target -1: none).
  void Push(int32_t v, int32_t target, double cost);
  bool Legal(int32_t u, int32_t v);
  void Collapse(int32_t u, int32_t v);
  // Marks the neighbours of v in mark_ with a new generation; returns it.
  uint32_t MarkNeighbours(int32_t v, std::vector<int32_t>* out);

  std::vector<Eigen::Vector3d> pos_;
  std::vector<std::array<int32_t, 3>> tri_;
  std::vector<char> tri_alive_;
  std::vector<std::vector<int32_t>> faces_;  // per vertex
  std::vector<Quadric> quadric_;
  std::vector<uint32_t> stamp_;
  // Each vertex's valid entry: its target (-1: none) and cost.
  std::vector<int32_t> target_;
  std::vector<double> best_;
  std::vector<char> boundary_;
  std::vector<uint32_t> mark_;
  uint32_t generation_ = 0;
  std::priority_queue<Entry> heap_;
  size_t alive_faces_ = 0;
  std::vector<int32_t> scratch_u_, scratch_v_, scratch_n_, scratch_c_;
  std::vector<std::pair<double, int32_t>> scratch_options_;
};

Decimator::Decimator(const Mesh& mesh)
    : pos_(mesh.positions),
      tri_(mesh.triangles),
      tri_alive_(mesh.triangles.size(), 1),
      faces_(mesh.positions.size()),
      quadric_(mesh.positions.size()),
      stamp_(mesh.positions.size(), 0),
      target_(mesh.positions.size(), -1),
      best_(mesh.positions.size(), 0.0),
      boundary_(mesh.positions.size(), 0),
      mark_(mesh.positions.size(), 0),
      alive_faces_(mesh.triangles.size()) {
  std::vector<std::pair<int32_t, int32_t>> edges;
  edges.reserve(tri_.size() * 3);
  for (size_t f = 0; f < tri_.size(); ++f) {
    const auto& t = tri_[f];
    const Eigen::Vector3d n =
        Cross(pos_[t[1]] - pos_[t[0]], pos_[t[2]] - pos_[t[0]]);
    const double twice_area = std::sqrt(n.dot(n));
    for (int k = 0; k < 3; ++k) {
      faces_[t[k]].push_back(static_cast<int32_t>(f));
      edges.emplace_back(std::min(t[k], t[(k + 1) % 3]),
                         std::max(t[k], t[(k + 1) % 3]));
    }
    if (!(twice_area > 0.0)) continue;
    const Eigen::Vector3d unit = n / twice_area;
    Quadric plane;
    plane.AddPlane(unit, -unit.dot(pos_[t[0]]), twice_area / 2.0);
    for (int k = 0; k < 3; ++k) quadric_[t[k]].Add(plane);
  }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    if (j - i == 1) boundary_[edges[i].first] = boundary_[edges[i].second] = 1;
    i = j;
  }
  for (size_t v = 0; v < pos_.size(); ++v) {
    if (!faces_[v].empty()) Schedule(static_cast<int32_t>(v), false);
  }
}

const std::vector<int32_t>& Decimator::Faces(int32_t v) {
  std::vector<int32_t>& f = faces_[v];
  f.erase(std::remove_if(f.begin(), f.end(),
                         [this](int32_t t) { return !tri_alive_[t]; }),
          f.end());
  return f;
}

uint32_t Decimator::MarkNeighbours(int32_t v, std::vector<int32_t>* out) {
  const uint32_t g = ++generation_;
  out->clear();
  for (int32_t f : Faces(v)) {
    for (int32_t w : tri_[f]) {
      if (w != v && mark_[w] != g) {
        mark_[w] = g;
        out->push_back(w);
      }
    }
  }
  return g;
}

void Decimator::Push(int32_t v, int32_t target, double cost) {
  ++stamp_[v];
  target_[v] = target;
  best_[v] = cost;
  if (target >= 0) heap_.push({cost, v, target, stamp_[v]});
}

void Decimator::Schedule(int32_t v, bool legal) {
  MarkNeighbours(v, &scratch_n_);
  if (!legal) {
    // The cheapest by cost alone (ties: the lower id), checked when popped.
    double best = 0.0;
    int32_t target = -1;
    for (int32_t w : scratch_n_) {
      const double cost = quadric_[v].Eval(quadric_[w], pos_[w]);
      if (target < 0 || cost < best || (cost == best && w < target)) {
        best = cost;
        target = w;
      }
    }
    Push(v, target, best);
    return;
  }
  std::vector<std::pair<double, int32_t>>& options = scratch_options_;
  options.clear();
  for (int32_t w : scratch_n_) {
    options.emplace_back(quadric_[v].Eval(quadric_[w], pos_[w]), w);
  }
  std::sort(options.begin(), options.end());
  for (const auto& [cost, w] : options) {
    if (!Legal(v, w)) continue;
    Push(v, w, cost);
    return;
  }
  Push(v, -1, 0.0);  // stuck until a neighbour's collapse changes it
}

bool Decimator::Legal(int32_t u, int32_t v) {
  const uint32_t gv = MarkNeighbours(v, &scratch_v_);
  // Shared faces (those holding both) and the link condition: the common
  // neighbours of u and v are exactly those faces' third vertices.
  int shared = 0;
  int32_t third[2] = {-1, -1};
  for (int32_t f : Faces(u)) {
    const auto& t = tri_[f];
    if (t[0] != v && t[1] != v && t[2] != v) continue;
    if (shared == 2) return false;
    for (int32_t w : t) {
      if (w != u && w != v) third[shared] = w;
    }
    ++shared;
  }
  if (shared == 0) return false;
  if (boundary_[u] && shared != 1) return false;  // would pinch the boundary
  if (!boundary_[u] && boundary_[v] && shared != 2) return false;
  int common = 0;
  std::vector<int32_t>& nu = scratch_u_;
  nu.clear();
  for (int32_t f : faces_[u]) {
    for (int32_t w : tri_[f]) {
      if (w == u || w == v || mark_[w] != gv) continue;
      if (w != third[0] && w != third[1]) return false;
      if (std::find(nu.begin(), nu.end(), w) == nu.end()) nu.push_back(w);
    }
  }
  common = static_cast<int>(nu.size());
  if (common != shared) return false;
  // No triangle flips or degenerates, and none duplicates one of v's (a
  // tetrahedron, or a component about to vanish).
  for (int32_t f : faces_[u]) {
    const auto& t = tri_[f];
    if (t[0] == v || t[1] == v || t[2] == v) continue;
    std::array<Eigen::Vector3d, 3> p = {pos_[t[0]], pos_[t[1]], pos_[t[2]]};
    const Eigen::Vector3d before = Cross(p[1] - p[0], p[2] - p[0]);
    for (int k = 0; k < 3; ++k) {
      if (t[k] == u) p[k] = pos_[v];
    }
    const Eigen::Vector3d after = Cross(p[1] - p[0], p[2] - p[0]);
    if (!(after.dot(before) > 0.0)) return false;
    if (after.dot(after) <= 1e-24 * before.dot(before)) return false;
    int32_t x = -1, y = -1;
    for (int32_t w : t) {
      if (w != u) (x < 0 ? x : y) = w;
    }
    if (mark_[x] == gv && mark_[y] == gv) {
      for (int32_t g : faces_[v]) {
        const auto& s = tri_[g];
        const bool has_x = s[0] == x || s[1] == x || s[2] == x;
        const bool has_y = s[0] == y || s[1] == y || s[2] == y;
        if (has_x && has_y) return false;
      }
    }
  }
  return true;
}

void Decimator::Collapse(int32_t u, int32_t v) {
  for (int32_t f : faces_[u]) {
    auto& t = tri_[f];
    if (t[0] == v || t[1] == v || t[2] == v) {
      tri_alive_[f] = 0;
      --alive_faces_;
      continue;
    }
    for (int32_t& w : t) {
      if (w == u) w = v;
    }
    faces_[v].push_back(f);
  }
  faces_[u].clear();
  quadric_[v].Add(quadric_[u]);
  boundary_[v] = boundary_[v] || boundary_[u];
  Push(u, -1, 0.0);  // u's entries are stale for good
  Schedule(v, false);
  // A neighbour's costs to others are unchanged; its cost to v only grew
  // (quadrics are positive semi-definite), or is new for u's neighbours.
  // So only a neighbour aiming at u or v needs a new scan; any other
  // takes v when v is now cheaper than its target.
  MarkNeighbours(v, &scratch_c_);
  for (int32_t w : scratch_c_) {
    if (target_[w] == u || target_[w] == v || target_[w] < 0) {
      Schedule(w, false);
      continue;
    }
    const double cost = quadric_[w].Eval(quadric_[v], pos_[v]);
    if (cost < best_[w] || (cost == best_[w] && v < target_[w])) {
      Push(w, v, cost);
    }
  }
}

size_t Decimator::Run(size_t max_faces) {
  while (alive_faces_ > max_faces && !heap_.empty()) {
    const Entry e = heap_.top();
    heap_.pop();
    if (e.stamp != stamp_[e.from]) continue;
    if (!Legal(e.from, e.to)) {
      Schedule(e.from, true);
      continue;
    }
    Collapse(e.from, e.to);
  }
  return alive_faces_;
}

Mesh Decimator::Result() const {
  Mesh out;
  out.positions = pos_;
  for (size_t f = 0; f < tri_.size(); ++f) {
    if (tri_alive_[f]) out.triangles.push_back(tri_[f]);
  }
  return out;
}

template <typename T>
void AppendLittleEndian(std::string* out, T value) {
  static_assert(sizeof(T) == 4 || sizeof(T) == 1);
  unsigned char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  const uint16_t one = 1;
  unsigned char first;
  std::memcpy(&first, &one, 1);
  if (first != 1) {  // big-endian host
    for (size_t i = 0; i < sizeof(T) / 2; ++i) {
      std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
    }
  }
  out->append(reinterpret_cast<const char*>(bytes), sizeof(T));
}

}  // namespace

absl::StatusOr<Mesh> SimplifyForPreview(const Mesh& mesh,
                                        const PreviewOptions& options) {
  if (options.max_faces < 4 || options.max_faces > 10'000'000) {
    return absl::InvalidArgumentError(
        absl::StrCat("preview: max_faces must be in [4, 10000000], got ",
                     options.max_faces));
  }
  const int64_t n = static_cast<int64_t>(mesh.positions.size());
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (int32_t v : mesh.triangles[f]) {
      if (v < 0 || v >= n) {
        return absl::InvalidArgumentError(absl::StrCat(
            "preview: triangle ", f, " has vertex ", v, " out of range"));
      }
    }
  }
  const size_t max_faces = static_cast<size_t>(options.max_faces);
  if (mesh.triangles.size() <= max_faces) return Compact(mesh);
  Decimator decimator(mesh);
  const size_t left = decimator.Run(max_faces);
  if (left > max_faces) {
    return absl::FailedPreconditionError(
        absl::StrCat("preview: the decimation stopped at ", left,
                     " triangles, above the limit of ", max_faces,
                     " (further collapses would break the surface's "
                     "topology)"));
  }
  return Compact(decimator.Result());
}

std::string EncodePreviewPly(const Mesh& mesh) {
  std::string out = absl::StrCat(
      "ply\nformat binary_little_endian 1.0\n"
      "comment TPR Search preview\n"
      "element vertex ",
      mesh.positions.size(),
      "\nproperty float x\nproperty float y\nproperty float z\n"
      "element face ",
      mesh.triangles.size(),
      "\nproperty list uchar int vertex_indices\nend_header\n");
  out.reserve(out.size() + mesh.positions.size() * 12 +
              mesh.triangles.size() * 13);
  for (const Eigen::Vector3d& p : mesh.positions) {
    for (int c = 0; c < 3; ++c) {
      AppendLittleEndian(&out, static_cast<float>(p[c]));
    }
  }
  const int32_t n = static_cast<int32_t>(mesh.positions.size());
  for (const auto& t : mesh.triangles) {
    AppendLittleEndian(&out, static_cast<uint8_t>(3));
    for (int32_t v : t) {
      assert(v >= 0 && v < n);
      (void)n;
      AppendLittleEndian(&out, v);
    }
  }
  return out;
}

absl::StatusOr<std::string> MakePreviewPly(const Mesh& mesh,
                                           const PreviewOptions& options) {
  absl::StatusOr<Mesh> simple = SimplifyForPreview(mesh, options);
  if (!simple.ok()) return simple.status();
  return EncodePreviewPly(*simple);
}

}  // namespace tpr::extract
