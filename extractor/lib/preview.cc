#include "extractor/lib/preview.h"

#include <array>
#include <cassert>
#include <cstdint>
#include <cstring>
#include <vector>

// GCC 12 sees OpenMesh's property vectors' default-constructed points as
// maybe uninitialized (a false positive, as in spectrum.cc).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>
#pragma GCC diagnostic pop

#include "absl/strings/str_cat.h"

namespace tpr::extract {
namespace {

// Double points: the quadrics are computed from the mesh's own doubles.
struct PreviewTraits : public OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  using Normal = OpenMesh::Vec3d;
};
using OmMesh = OpenMesh::TriMesh_ArrayKernelT<PreviewTraits>;

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

absl::StatusOr<OmMesh> ToOpenMesh(const Mesh& mesh) {
  OmMesh om;
  om.reserve(mesh.positions.size(), mesh.triangles.size() * 3 / 2 + 3,
             mesh.triangles.size());
  std::vector<OmMesh::VertexHandle> handles;
  handles.reserve(mesh.positions.size());
  for (const Eigen::Vector3d& p : mesh.positions) {
    handles.push_back(om.add_vertex(OmMesh::Point(p.x(), p.y(), p.z())));
  }
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const auto& t = mesh.triangles[f];
    if (!om.add_face(handles[t[0]], handles[t[1]], handles[t[2]]).is_valid()) {
      return absl::InvalidArgumentError(
          absl::StrCat("preview: triangle ", f, " (", t[0], ", ", t[1], ", ",
                       t[2], ") is not manifold with the triangles before it"));
    }
  }
  return om;
}

Mesh FromOpenMesh(const OmMesh& om) {
  Mesh out;
  out.positions.reserve(om.n_vertices());
  for (const OmMesh::VertexHandle v : om.vertices()) {
    const OmMesh::Point& p = om.point(v);
    out.positions.emplace_back(p[0], p[1], p[2]);
  }
  out.triangles.reserve(om.n_faces());
  for (const OmMesh::FaceHandle f : om.faces()) {
    std::array<int32_t, 3> t;
    int k = 0;
    for (const OmMesh::VertexHandle v : om.fv_range(f)) t[k++] = v.idx();
    out.triangles.push_back(t);
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
  absl::StatusOr<OmMesh> om = ToOpenMesh(mesh);
  if (!om.ok()) return om.status();
  OpenMesh::Decimater::DecimaterT<OmMesh> decimater(*om);
  OpenMesh::Decimater::ModQuadricT<OmMesh>::Handle quadric;
  decimater.add(quadric);
  decimater.module(quadric).unset_max_err();
  if (!decimater.initialize()) {
    return absl::InternalError("preview: the decimater did not initialize");
  }
  decimater.decimate_to_faces(0, max_faces);
  om->garbage_collection();
  if (om->n_faces() > max_faces) {
    return absl::FailedPreconditionError(
        absl::StrCat("preview: the decimater stopped at ", om->n_faces(),
                     " triangles, above the limit of ", max_faces,
                     " (collapses would break the surface's topology)"));
  }
  return Compact(FromOpenMesh(*om));
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
