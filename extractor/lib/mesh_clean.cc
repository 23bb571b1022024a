// Mesh cleaning steps (mesh_clean.h). Hand-written rather than OpenMesh's
// halfedge build: OpenMesh's add_face refuses (and drops) the very faces we
// must name in an error or repair, and needs a mutable halfedge structure
// for what are here a few sorts over flat arrays.
#include "extractor/lib/mesh_clean.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cassert>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "common/status_macros.h"
#include "extractor/lib/debris.h"
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
  int32_t face;  // < 2^31 (ValidatePolygonSoup); 16 bytes in all
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
      halfedges.push_back({key, static_cast<int32_t>(f), a < b});
    }
  }
  std::sort(halfedges.begin(), halfedges.end());
  return halfedges;
}

std::string EdgeName(uint64_t key) {
  return absl::StrCat("(", key >> 32, ", ", key & 0xffffffffu, ")");
}

// Link joins the two triangles of an edge that has exactly two.
struct Link {
  int64_t f, g;
  bool flip;  // g must be flipped relative to f
  uint64_t key;
};

// BuildLinks returns one Link per edge of exactly two triangles, in edge
// order, and counts the edges of three or more in *non_manifold_edges
// (when not null). Such an edge links nothing: each of its triangles has
// it as a border, which is how it is cut into sheets.
std::vector<Link> BuildLinks(const Triangles& triangles,
                             int64_t* non_manifold_edges) {
  const std::vector<HalfEdge> halfedges = SortedHalfEdges(triangles);
  std::vector<Link> links;
  links.reserve(halfedges.size() / 2);
  for (size_t i = 0; i < halfedges.size();) {
    size_t j = i + 1;
    while (j < halfedges.size() && halfedges[j].key == halfedges[i].key) ++j;
    if (j - i == 2) {
      // Consistently oriented neighbours traverse their shared edge in
      // opposite directions.
      links.push_back({halfedges[i].face, halfedges[i + 1].face,
                       halfedges[i].forward == halfedges[i + 1].forward,
                       halfedges[i].key});
    } else if (j - i > 2 && non_manifold_edges != nullptr) {
      ++*non_manifold_edges;
    }
    i = j;
  }
  return links;
}

// Orient flips triangles so that every kept link is consistent, and returns
// how many it flipped. Breadth-first over faces, flipping to agree with the
// first face; then per component the majority's orientation is kept, and a
// closed component (three kept links per face, none cut) is turned to a
// positive signed volume (outward normals). A link that contradicts the
// orientation already given is INVALID_ARGUMENT when `cut` is null, else
// marked in *cut and ignored (the surface is cut open there).
absl::StatusOr<int64_t> Orient(const std::vector<Eigen::Vector3d>& positions,
                               const std::vector<Link>& links,
                               std::vector<char>* cut, Triangles* triangles) {
  const int64_t nf = static_cast<int64_t>(triangles->size());
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
  std::vector<int8_t> flip(nf, -1);
  std::vector<int64_t> queue;
  std::vector<int64_t> component;
  int64_t reoriented = 0;
  for (int64_t seed = 0; seed < nf; ++seed) {
    if (flip[seed] >= 0) continue;
    flip[seed] = 0;
    queue.assign(1, seed);
    component.clear();
    bool closed = true;
    for (size_t q = 0; q < queue.size(); ++q) {
      const int64_t f = queue[q];
      component.push_back(f);
      if (offsets[f + 1] - offsets[f] != 3) closed = false;
      for (int64_t a = offsets[f]; a < offsets[f + 1]; ++a) {
        const auto [g, link] = adjacency[a];
        if (cut != nullptr && (*cut)[link]) continue;
        const int8_t want = flip[f] ^ (links[link].flip ? 1 : 0);
        if (flip[g] < 0) {
          flip[g] = want;
          queue.push_back(g);
        } else if (flip[g] != want) {
          if (cut == nullptr) {
            return absl::InvalidArgumentError(absl::StrCat(
                "non-orientable surface: triangles around edge ",
                EdgeName(links[link].key), " cannot be oriented consistently"));
          }
          (*cut)[link] = 1;
          closed = false;
        }
      }
    }
    int64_t flipped = 0;
    for (int64_t f : component) flipped += flip[f];
    bool invert = 2 * flipped > static_cast<int64_t>(component.size());
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

// CornerOf returns the corner id 3f + k of vertex v in triangle f.
int64_t CornerOf(const Triangles& triangles, int64_t f, uint32_t v) {
  for (int k = 0; k < 3; ++k) {
    if (static_cast<uint32_t>(triangles[f][k]) == v) return 3 * f + k;
  }
  return -1;
}

// SplitFans gives each fan of a vertex its own vertex: corners of triangles
// meeting at a vertex are joined across each kept (not cut) link; the fan
// of the vertex's first corner keeps its id, every other fan gets a copy of
// the position appended to *positions. Counts split vertices and copies in
// *repair.
void SplitFans(const std::vector<Link>& links, const std::vector<char>& cut,
               std::vector<Eigen::Vector3d>* positions, Triangles* triangles,
               ManifoldRepair* repair) {
  const int64_t nf = static_cast<int64_t>(triangles->size());
  const int64_t nv = static_cast<int64_t>(positions->size());
  DisjointSets corners(3 * nf);
  for (size_t i = 0; i < links.size(); ++i) {
    if (cut[i]) continue;
    const uint32_t a = static_cast<uint32_t>(links[i].key >> 32);
    const uint32_t b = static_cast<uint32_t>(links[i].key & 0xffffffffu);
    corners.Union(CornerOf(*triangles, links[i].f, a),
                  CornerOf(*triangles, links[i].g, a));
    corners.Union(CornerOf(*triangles, links[i].f, b),
                  CornerOf(*triangles, links[i].g, b));
  }
  std::vector<int32_t> fan_vertex(3 * nf, -1);  // by root corner
  std::vector<char> has_fan(nv, 0), split(nv, 0);
  for (int64_t c = 0; c < 3 * nf; ++c) {
    int32_t& v = (*triangles)[c / 3][c % 3];
    const int64_t root = corners.Find(c);
    if (fan_vertex[root] < 0) {
      if (!has_fan[v]) {
        has_fan[v] = 1;
        fan_vertex[root] = v;
      } else {
        if (!split[v]) {
          split[v] = 1;
          ++repair->split_vertices;
        }
        fan_vertex[root] = static_cast<int32_t>(positions->size());
        positions->push_back((*positions)[v]);
        ++repair->added_vertices;
      }
    }
    v = fan_vertex[root];
  }
}

// FacesOnFaultyEdges returns, for every edge of three or more triangles or
// of two triangles traversing it in the same direction, all its triangles
// but the first (ascending, without repeats).
std::vector<int64_t> FacesOnFaultyEdges(const Triangles& triangles) {
  const std::vector<HalfEdge> halfedges = SortedHalfEdges(triangles);
  std::vector<int64_t> bad;
  for (size_t i = 0; i < halfedges.size();) {
    size_t j = i + 1;
    while (j < halfedges.size() && halfedges[j].key == halfedges[i].key) ++j;
    if (j - i > 2 ||
        (j - i == 2 && halfedges[i].forward == halfedges[i + 1].forward)) {
      for (size_t k = i + 1; k < j; ++k) bad.push_back(halfedges[k].face);
    }
    i = j;
  }
  std::sort(bad.begin(), bad.end());
  bad.erase(std::unique(bad.begin(), bad.end()), bad.end());
  return bad;
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
      return absl::InvalidArgumentError(
          absl::StrCat("vertex ", v, ": coordinate ",
                       soup.positions[v].cwiseAbs().maxCoeff(),
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
        return absl::InvalidArgumentError(
            absl::StrCat("face ", f, " references vertex ", v,
                         "; the mesh has ", nv, " vertices"));
      }
    }
    triangle_count += static_cast<int64_t>(polygon.size()) - 2;
  }
  if (triangle_count > options.max_faces ||
      triangle_count > std::numeric_limits<int32_t>::max()) {
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
  for (const Link& l : BuildLinks(triangles, nullptr)) {
    const uint32_t a = static_cast<uint32_t>(l.key >> 32);
    const uint32_t b = static_cast<uint32_t>(l.key & 0xffffffffu);
    corners.Union(CornerOf(triangles, l.f, a), CornerOf(triangles, l.g, a));
    corners.Union(CornerOf(triangles, l.f, b), CornerOf(triangles, l.g, b));
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
  const std::vector<Link> links = BuildLinks(*triangles, nullptr);
  return Orient(positions, links, nullptr, triangles);
}

ManifoldRepair RepairNonManifold(std::vector<Eigen::Vector3d>* positions,
                                 Triangles* triangles) {
  ManifoldRepair repair;
  // Round 0 does the work; a later round runs only when a cut edge was
  // glued back by the vertex split (its faces still share both ends), after
  // detaching the faces of every such edge but the first. Detaching never
  // creates a new fault, so the third round finds none.
  for (int round = 0;; ++round) {
    int64_t non_manifold_edges = 0;
    const std::vector<Link> links = BuildLinks(*triangles, &non_manifold_edges);
    std::vector<char> cut(links.size(), 0);
    // Cannot fail: conflicts become cuts.
    const int64_t flipped = *Orient(*positions, links, &cut, triangles);
    repair.reoriented += flipped;
    int64_t cuts = 0;
    for (char c : cut) cuts += c;
    if (round == 0) {
      repair.non_manifold_edges = non_manifold_edges;
      repair.orientation_cuts = cuts;
    }
    SplitFans(links, cut, positions, triangles, &repair);
    const std::vector<int64_t> bad = FacesOnFaultyEdges(*triangles);
    if (bad.empty() || round >= 3) {
      assert(bad.empty());
      break;
    }
    for (int64_t f : bad) {
      for (int32_t& v : (*triangles)[f]) {
        positions->push_back((*positions)[v]);
        v = static_cast<int32_t>(positions->size() - 1);
      }
    }
    repair.detached_triangles += static_cast<int64_t>(bad.size());
    repair.added_vertices += 3 * static_cast<int64_t>(bad.size());
  }
  return repair;
}

int64_t CompactVertices(std::vector<Eigen::Vector3d>* positions,
                        Triangles* triangles, VertexOrder order) {
  const int64_t nv = static_cast<int64_t>(positions->size());
  if (order == VertexOrder::kFirstReference) {
    std::vector<int32_t> remap(nv, -1);
    std::vector<Eigen::Vector3d> kept;
    for (auto& t : *triangles) {
      for (int32_t& v : t) {
        int32_t& r = remap[v];
        if (r < 0) {
          r = static_cast<int32_t>(kept.size());
          kept.push_back((*positions)[v]);
        }
        v = r;
      }
    }
    *positions = std::move(kept);
    return nv - static_cast<int64_t>(positions->size());
  }
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
  const int64_t degenerate =
      soup.reader_dropped_degenerate +
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
    // Far from the origin, float precision (what files are read with)
    // merges nearby vertices: say so rather than only "degenerate".
    Eigen::Vector3d lo = soup.positions[0], hi = soup.positions[0];
    double magnitude = 0.0;
    for (const Eigen::Vector3d& p : soup.positions) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
      magnitude = std::max(magnitude, p.cwiseAbs().maxCoeff());
    }
    const double span = (hi - lo).maxCoeff();
    const std::string hint =
        degenerate > 0 && magnitude > 1e6 * span
            ? absl::StrCat("; the coordinates reach ", magnitude,
                           " but span only ", span,
                           ": at float precision (24 bits, how files are "
                           "read) detail below ",
                           magnitude * 6e-8,
                           " is lost, so move the mesh "
                           "near the origin")
            : "";
    return absl::InvalidArgumentError(absl::StrCat(
        "mesh has no faces left after dropping ", degenerate,
        " degenerate and ", duplicates, " duplicate triangles", hint));
  }
  const ManifoldRepair repair = RepairNonManifold(&soup.positions, &triangles);
  if (repair.non_manifold_edges > 0 || repair.split_vertices > 0 ||
      repair.orientation_cuts > 0 || repair.detached_triangles > 0) {
    warnings.push_back(absl::StrCat(
        "repaired non-manifold input by splitting it into manifold sheets: ",
        repair.non_manifold_edges, " edges shared by 3 or more triangles, ",
        repair.split_vertices,
        " vertices whose triangles form 2 or more fans (",
        repair.added_vertices, " vertex copies added)",
        repair.orientation_cuts > 0
            ? absl::StrCat(", ", repair.orientation_cuts,
                           " edges cut open to orient a non-orientable surface")
            : "",
        repair.detached_triangles > 0
            ? absl::StrCat(", ", repair.detached_triangles,
                           " triangles detached")
            : ""));
  }
  if (repair.reoriented > 0) {
    warnings.push_back(absl::StrCat("reoriented ", repair.reoriented,
                                    " triangles for a consistent orientation"));
  }
  const DebrisDropped debris = DropDebris(soup.positions, &triangles);
  if (debris.components > 0) warnings.push_back(DebrisWarning(debris));
  const int64_t unreferenced =
      CompactVertices(&soup.positions, &triangles) - debris.vertices;
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
  loaded.stats.non_manifold_edges = repair.non_manifold_edges;
  loaded.stats.non_manifold_vertices = repair.split_vertices;
  loaded.stats.orientation_cuts = repair.orientation_cuts;
  loaded.warnings = std::move(warnings);
  return loaded;
}

}  // namespace tpr::extract
