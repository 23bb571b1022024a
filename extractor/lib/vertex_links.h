// The 1-ring of every vertex, as the mesh's triangles give it: the one
// neighbourhood structure of the extractor. MeshGraph (geodesic.h) owns one
// and serves it as links() and one_ring(); Critical Point Analysis (4.3),
// the angle defects and the band segments (5.2-5.3) read it.
//
//   VertexLinks links = VertexLinks::Build(mesh);  // or graph.links()
//   for (int32_t u : links.fan(v)) { ... }          // fan order
//   for (const int32_t* p = links.link_begin(v); p != links.link_end(v);
//        p += 2) { ... }                            // link edges (p[0], p[1])
#ifndef TPR_EXTRACTOR_LIB_VERTEX_LINKS_H_
#define TPR_EXTRACTOR_LIB_VERTEX_LINKS_H_

#include <cstdint>
#include <vector>

#include "absl/types/span.h"
#include "extractor/lib/mesh.h"

namespace tpr::extract {

// VertexLinks holds, per vertex v:
// - the link edges: the edge opposite v in each incident triangle, as the
//   pair (a, b) of triangle (v, a, b), in triangle order;
// - the neighbours: the distinct vertices of those link edges, sorted;
// - the fan: the same neighbours (v itself excluded) in the cyclic order of
//   v's triangle fan, counter-clockwise seen from outside for consistently
//   oriented triangles. For a boundary vertex the fan starts at a boundary
//   edge and is open (its last and first entries are not adjacent). For a
//   fan that is not a single disk or half-disk (intake rejects these) each
//   neighbour still appears once.
// Only mesh edges: never the unfolded shortcut arcs MeshGraph may add for
// distances, which are not part of the 1-ring. The arcs of a ring whose
// vertices a wavefront has passed decide whether the wavefront meets itself
// there (4.2, 4.3). Immutable after Build; thread-safe to share.
class VertexLinks {
 public:
  VertexLinks() = default;

  // Build returns the links of `mesh`. Precondition: every index in range
  // (intake guarantees it). Cost O(f) time and memory (fans are small: the
  // fan order is a quadratic scan over each vertex's about 6 link edges).
  // Thread-safe.
  static VertexLinks Build(const Mesh& mesh);

  int32_t num_vertices() const {
    return static_cast<int32_t>(nbr_offsets_.empty() ? 0
                                                     : nbr_offsets_.size() - 1);
  }
  // Distinct mesh-edge neighbours of v, sorted. Precondition for all
  // accessors: 0 <= v < num_vertices().
  const int32_t* neighbors_begin(int32_t v) const {
    return nbr_.data() + nbr_offsets_[v];
  }
  const int32_t* neighbors_end(int32_t v) const {
    return nbr_.data() + nbr_offsets_[v + 1];
  }
  int32_t degree(int32_t v) const {
    return static_cast<int32_t>(nbr_offsets_[v + 1] - nbr_offsets_[v]);
  }
  // Link edges of v as vertex pairs (a, b): triangle (v, a, b).
  const int32_t* link_begin(int32_t v) const {
    return link_.data() + 2 * link_offsets_[v];
  }
  const int32_t* link_end(int32_t v) const {
    return link_.data() + 2 * link_offsets_[v + 1];
  }
  // The neighbours of v in fan order (see the class comment).
  absl::Span<const int32_t> fan(int32_t v) const {
    return absl::MakeConstSpan(fan_.data() + fan_offsets_[v],
                               fan_offsets_[v + 1] - fan_offsets_[v]);
  }

 private:
  std::vector<int64_t> link_offsets_;
  std::vector<int32_t> link_;  // Pairs.
  std::vector<int64_t> nbr_offsets_;
  std::vector<int32_t> nbr_;
  std::vector<int64_t> fan_offsets_;
  std::vector<int32_t> fan_;
};

}  // namespace tpr::extract

#endif  // TPR_EXTRACTOR_LIB_VERTEX_LINKS_H_
