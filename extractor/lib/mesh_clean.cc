// Mesh cleaning steps (mesh_clean.h). Hand-written rather than OpenMesh's
// halfedge build: OpenMesh's add_face refuses (and drops) the very faces we
// must name in an error or repair, and needs a mutable halfedge structure
// for what are here a few sorts over flat arrays.
#include "extractor/lib/mesh_clean.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "common/status_macros.h"
#include "extractor/lib/disjoint_sets.h"
#include "extractor/lib/mesh_io_text.h"  // the limit messages

namespace tpr::extract {
namespace {

// A triangle whose doubled area is at most this times its longest squared
// edge is degenerate (collinear up to rounding). Scale-free, so it treats a
// millimetre mesh and a kilometre mesh alike.
constexpr double kDegenerateRatio = 1e-12;

// One triangle side, keyed by its undirected edge.
struct HalfEdge {
  uint64_t key;  // (min << 32) | max
  int64_t face;
  bool forward;  // traversed min -> max
  bool operator<(const HalfEdge& o) const {
    return key != o.key ? key < o.key : face < o.face;
  }
};

// SortedHalfEdges returns the 3F sides, sorted so that each undirected
// edge's sides are adjacent (then by face). O(F log F), no hash table.
std::vector<HalfEdge> SortedHalfEdges(const Triangles& triangles) {
  std::vector<HalfEdge> halfedges;
  halfedges.reserve(3 * triangles.size());
  for (size_t f = 0; f < triangles.size(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = static_cast<uint32_t>(triangles[f][k]);
      const uint32_t b = static_cast<uint32_t>(triangles[f][(k + 1) % 3]);
      const uint64_t key = a < b ? (static_cast<uint64_t>(a) << 32) | b
                                 : (static_cast<uint64_t>(b) << 32) | a;
      halfedges.push_back({key, static_cast<int64_t>(f), a < b});
    }
  }
  std::sort(halfedges.begin(), halfedges.end());
  return halfedges;
}

std::string EdgeName(uint64_t key) {
  return absl::StrCat("(", key >> 32, ", ", key & 0xffffffffu, ")");
}

}  // namespace

absl::Status ValidatePolygonSoup(const PolygonSoup& soup,
                                 const IntakeOptions& options) {
  const int64_t nv = static_cast<int64_t>(soup.positions.size());
  if (nv > options.max_vertices) return mesh_io::TooManyVertices(nv, options);
  if (nv == 0) return absl::InvalidArgumentError("mesh has no vertices");
  if (soup.num_polygons() <= 0) {
    return absl::InvalidArgumentError("mesh has no faces");
  }
  for (int64_t v = 0; v < nv; ++v) {
    if (!soup.positions[v].allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("vertex ", v, " has a non-finite coordinate"));
    }
    if (soup.positions[v].cwiseAbs().maxCoeff() > kMaxCoordinate) {
      return absl::InvalidArgumentError(absl::StrCat(
          "vertex ", v, ": coordinate ", soup.positions[v].cwiseAbs().maxCoeff(),
          " exceeds the supported magnitude ", kMaxCoordinate,
          " (mesh_clean.h kMaxCoordinate)"));
    }
  }
  int64_t triangle_count = 0;
  for (int64_t f = 0; f < soup.num_polygons(); ++f) {
    const absl::Span<const int32_t> polygon = soup.polygon(f);
    if (polygon.size() < 3) {
      return absl::InvalidArgumentError(
          absl::StrCat("face ", f, " has ", polygon.size(),
                       " vertices; at least 3 are needed"));
    }
    for (int32_t v : polygon) {
      if (v < 0 || v >= nv) {
        return absl::InvalidArgumentError(absl::StrCat(
            "face ", f, " references vertex ", v, "; the mesh has ", nv,
            " vertices"));
      }
    }
    triangle_count += static_cast<int64_t>(polygon.size()) - 2;
  }
  if (triangle_count > options.max_faces) {
    return mesh_io::TooManyFaces(triangle_count, options);
  }
  return absl::OkStatus();
}

Triangles FanTriangulate(const PolygonSoup& soup) {
  Triangles triangles;
  triangles.reserve(soup.corners.size() - 2 * soup.num_polygons());
  for (int64_t p = 0; p < soup.num_polygons(); ++p) {
    const absl::Span<const int32_t> polygon = soup.polygon(p);
    for (size_t k = 1; k + 1 < polygon.size(); ++k) {
      triangles.push_back({polygon[0], polygon[k], polygon[k + 1]});
    }
  }
  return triangles;
}

int64_t DropDegenerateTriangles(const std::vector<Eigen::Vector3d>& positions,
                                Triangles* triangles) {
  size_t out = 0;
  for (const auto& t : *triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;
    const Eigen::Vector3d e0 = positions[t[1]] - positions[t[0]];
    const Eigen::Vector3d e1 = positions[t[2]] - positions[t[0]];
    const Eigen::Vector3d e2 = positions[t[2]] - positions[t[1]];
    const double longest =
        std::max({e0.squaredNorm(), e1.squaredNorm(), e2.squaredNorm()});
    if (e0.cross(e1).norm() <= kDegenerateRatio * longest) continue;
    (*triangles)[out++] = t;
  }
  const int64_t dropped = static_cast<int64_t>(triangles->size() - out);
  triangles->resize(out);
  return dropped;
}

int64_t DropDuplicateTriangles(Triangles* triangles) {
  std::vector<std::pair<std::array<int32_t, 3>, int64_t>> keys;
  keys.reserve(triangles->size());
  for (size_t f = 0; f < triangles->size(); ++f) {
    std::array<int32_t, 3> k = (*triangles)[f];
    std::sort(k.begin(), k.end());
    keys.emplace_back(k, static_cast<int64_t>(f));
  }
  std::sort(keys.begin(), keys.end());
  std::vector<char> drop(triangles->size(), 0);
  int64_t duplicates = 0;
  for (size_t i = 1; i < keys.size(); ++i) {
    if (keys[i].first == keys[i - 1].first) {
      drop[keys[i].second] = 1;
      ++duplicates;
    }
  }
  if (duplicates > 0) {
    size_t out = 0;
    for (size_t f = 0; f < triangles->size(); ++f) {
      if (!drop[f]) (*triangles)[out++] = (*triangles)[f];
    }
    triangles->resize(out);
  }
  return duplicates;
}

absl::Status CheckManifold(int64_t num_vertices, const Triangles& triangles) {
  const int64_t nf = static_cast<int64_t>(triangles.size());
  const std::vector<HalfEdge> halfedges = SortedHalfEdges(triangles);
  // Non-manifold edges first: the sorted order names the smallest such edge.
  for (size_t i = 0; i < halfedges.size();) {
    size_t j = i + 1;
    while (j < halfedges.size() && halfedges[j].key == halfedges[i].key) ++j;
    if (j - i > 2) {
      return absl::InvalidArgumentError(absl::StrCat(
          "non-manifold edge ", EdgeName(halfedges[i].key), ": shared by ",
          j - i, " triangles (at most 2 allowed)"));
    }
    i = j;
  }
  // Non-manifold vertices: corners (f, k) of triangles meeting at a vertex
  // are linked across each interior edge they share; a manifold vertex's
  // corners then form one set (its single fan), a pinch vertex several.
  DisjointSets corners(3 * nf);
  auto corner_of = [&](int64_t f, uint32_t v) -> int64_t {
    for (int k = 0; k < 3; ++k) {
      if (static_cast<uint32_t>(triangles[f][k]) == v) return 3 * f + k;
    }
    return -1;
  };
  for (size_t i = 0; i + 1 < halfedges.size(); ++i) {
    if (halfedges[i].key != halfedges[i + 1].key) continue;
    const uint32_t a = static_cast<uint32_t>(halfedges[i].key >> 32);
    const uint32_t b = static_cast<uint32_t>(halfedges[i].key & 0xffffffffu);
    const int64_t f = halfedges[i].face, g = halfedges[i + 1].face;
    corners.Union(corner_of(f, a), corner_of(g, a));
    corners.Union(corner_of(f, b), corner_of(g, b));
    ++i;
  }
  std::vector<int64_t> fan(num_vertices, -1);
  int64_t worst = -1;
  for (int64_t c = 0; c < 3 * nf; ++c) {
    const int32_t v = triangles[c / 3][c % 3];
    const int64_t root = corners.Find(c);
    if (fan[v] < 0) {
      fan[v] = root;
    } else if (fan[v] != root && (worst < 0 || v < worst)) {
      worst = v;
    }
  }
  if (worst >= 0) {
    std::vector<int64_t> roots;
    for (int64_t c = 0; c < 3 * nf; ++c) {
      if (triangles[c / 3][c % 3] == worst) roots.push_back(corners.Find(c));
    }
    std::sort(roots.begin(), roots.end());
    roots.erase(std::unique(roots.begin(), roots.end()), roots.end());
    return absl::InvalidArgumentError(absl::StrCat(
        "non-manifold vertex ", worst, ": its triangles form ", roots.size(),
        " separate fans (one disk or half-disk allowed)"));
  }
  return absl::OkStatus();
}

absl::StatusOr<int64_t> OrientConsistently(
    const std::vector<Eigen::Vector3d>& positions, Triangles* triangles) {
  const int64_t nf = static_cast<int64_t>(triangles->size());
  const std::vector<HalfEdge> halfedges = SortedHalfEdges(*triangles);
  // Links between the two triangles of each interior edge.
  struct Link {
    int64_t f, g;
    bool flip;  // g must be flipped relative to f
    uint64_t key;
  };
  std::vector<Link> links;
  links.reserve(halfedges.size() / 2);
  for (size_t i = 0; i + 1 < halfedges.size(); ++i) {
    if (halfedges[i].key != halfedges[i + 1].key) continue;
    const HalfEdge& h0 = halfedges[i];
    const HalfEdge& h1 = halfedges[i + 1];
    // Consistently oriented neighbours traverse their shared edge in
    // opposite directions.
    links.push_back({h0.face, h1.face, h0.forward == h1.forward, h0.key});
    ++i;
  }
  std::vector<int64_t> offsets(nf + 1, 0);
  for (const Link& l : links) {
    ++offsets[l.f + 1];
    ++offsets[l.g + 1];
  }
  for (int64_t f = 0; f < nf; ++f) offsets[f + 1] += offsets[f];
  std::vector<std::pair<int64_t, size_t>> adjacency(offsets[nf]);
  {
    std::vector<int64_t> fill(offsets.begin(), offsets.end() - 1);
    for (size_t i = 0; i < links.size(); ++i) {
      adjacency[fill[links[i].f]++] = {links[i].g, i};
      adjacency[fill[links[i].g]++] = {links[i].f, i};
    }
  }
  // Breadth-first over faces, flipping to agree with the first face; then
  // per component keep the majority's orientation, and for a closed
  // component make the signed volume positive (outward normals).
  std::vector<int8_t> flip(nf, -1);
  std::vector<int64_t> queue;
  std::vector<int64_t> component;
  int64_t reoriented = 0;
  for (int64_t seed = 0; seed < nf; ++seed) {
    if (flip[seed] >= 0) continue;
    flip[seed] = 0;
    queue.assign(1, seed);
    component.clear();
    for (size_t q = 0; q < queue.size(); ++q) {
      const int64_t f = queue[q];
      component.push_back(f);
      for (int64_t a = offsets[f]; a < offsets[f + 1]; ++a) {
        const auto [g, link] = adjacency[a];
        const int8_t want = flip[f] ^ (links[link].flip ? 1 : 0);
        if (flip[g] < 0) {
          flip[g] = want;
          queue.push_back(g);
        } else if (flip[g] != want) {
          return absl::InvalidArgumentError(absl::StrCat(
              "non-orientable surface: triangles around edge ",
              EdgeName(links[link].key), " cannot be oriented consistently"));
        }
      }
    }
    int64_t flipped = 0;
    for (int64_t f : component) flipped += flip[f];
    bool invert = 2 * flipped > static_cast<int64_t>(component.size());
    // A closed component (every triangle has three neighbours) decides by
    // signed volume.
    bool closed = true;
    for (int64_t f : component) {
      if (offsets[f + 1] - offsets[f] != 3) {
        closed = false;
        break;
      }
    }
    if (closed) {
      double volume = 0.0;
      for (int64_t f : component) {
        const auto& t = (*triangles)[f];
        const double v6 =
            positions[t[0]].dot(positions[t[1]].cross(positions[t[2]]));
        volume += flip[f] ? -v6 : v6;
      }
      invert = volume < 0;
    }
    for (int64_t f : component) {
      if ((flip[f] != 0) != invert) {
        std::swap((*triangles)[f][1], (*triangles)[f][2]);
        ++reoriented;
      }
    }
  }
  return reoriented;
}

int64_t CompactVertices(std::vector<Eigen::Vector3d>* positions,
                        Triangles* triangles) {
  const int64_t nv = static_cast<int64_t>(positions->size());
  std::vector<int32_t> remap(nv, -1);
  for (const auto& t : *triangles) {
    for (int32_t v : t) remap[v] = 0;
  }
  int32_t used = 0;
  for (int64_t v = 0; v < nv; ++v) {
    if (remap[v] == 0) {
      remap[v] = used;
      (*positions)[used++] = (*positions)[v];
    }
  }
  positions->resize(used);
  for (auto& t : *triangles) {
    for (int32_t& v : t) v = remap[v];
  }
  return nv - used;
}

absl::StatusOr<LoadedMesh> CleanPolygonSoup(PolygonSoup soup,
                                            const IntakeOptions& options) {
  TPR_RETURN_IF_ERROR(ValidatePolygonSoup(soup, options));
  std::vector<std::string> warnings = std::move(soup.warnings);
  Triangles triangles = FanTriangulate(soup);
  soup.corners = {};
  soup.offsets = {};
  const int64_t degenerate = soup.reader_dropped_degenerate +
                             DropDegenerateTriangles(soup.positions, &triangles);
  const int64_t duplicates = DropDuplicateTriangles(&triangles);
  if (degenerate > 0) {
    warnings.push_back(absl::StrCat("dropped ", degenerate,
                                    " degenerate (zero-area) triangles"));
  }
  if (duplicates > 0) {
    warnings.push_back(
        absl::StrCat("dropped ", duplicates, " duplicate triangles"));
  }
  if (triangles.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "mesh has no faces left after dropping ", degenerate,
        " degenerate and ", duplicates, " duplicate triangles"));
  }
  TPR_RETURN_IF_ERROR(CheckManifold(
      static_cast<int64_t>(soup.positions.size()), triangles));
  TPR_ASSIGN_OR_RETURN(const int64_t reoriented,
                       OrientConsistently(soup.positions, &triangles));
  if (reoriented > 0) {
    warnings.push_back(absl::StrCat(
        "reoriented ", reoriented, " triangles for a consistent orientation"));
  }
  const int64_t unreferenced = CompactVertices(&soup.positions, &triangles);
  if (unreferenced > 0) {
    warnings.push_back(absl::StrCat("removed ", unreferenced,
                                    " vertices no triangle references"));
  }
  LoadedMesh loaded;
  loaded.mesh.positions = std::move(soup.positions);
  loaded.mesh.triangles = std::move(triangles);
  loaded.stats = ComputeMeshStats(loaded.mesh);
  loaded.stats.dropped_degenerate_faces = degenerate;
  loaded.stats.dropped_duplicate_faces = duplicates;
  loaded.stats.unreferenced_vertices = unreferenced;
  loaded.warnings = std::move(warnings);
  return loaded;
}

}  // namespace tpr::extract
