#include "extractor/service/convert.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "common/signature_limits.h"
#include "common/status_macros.h"

// The version comes from CMake's project() through tpr_extract's compile
// definition when available; the extractor/CMakeLists.txt sets it PRIVATE on
// tpr_extract only, so fall back to the same number here.
#ifndef TPR_VERSION_STRING
#define TPR_VERSION_STRING "0.1.0"
#endif

namespace tpr::extractor {

const char kExtractorVersion[] = TPR_VERSION_STRING;

namespace {

// SetMethods sets the topology method and the handle treatment of
// `options` from `proto`; UNSPECIFIED keeps the library's default.
// INVALID_ARGUMENT for a value this build does not know.
absl::Status SetMethods(const v1::ExtractOptions& proto,
                        extract::Options* options) {
  switch (proto.topology()) {
    case v1::TOPOLOGY_METHOD_UNSPECIFIED:
      break;  // the library's default
    case v1::TOPOLOGY_METHOD_PERSISTENCE:
      options->topology = extract::TopologyMethod::kPersistence;
      break;
    case v1::TOPOLOGY_METHOD_PAPER:
      options->topology = extract::TopologyMethod::kPaper;
      break;
    default:  // a newer client's value
      return absl::InvalidArgumentError(absl::StrCat(
          "options.topology has unknown value ", proto.topology(),
          " (1 = TOPOLOGY_METHOD_PERSISTENCE, 2 = TOPOLOGY_METHOD_PAPER)"));
  }
  switch (proto.handles()) {
    case v1::HANDLE_TREATMENT_UNSPECIFIED:
      break;  // the library's default
    case v1::HANDLE_TREATMENT_CUT:
      options->cut_handles = true;
      break;
    case v1::HANDLE_TREATMENT_KEEP:
      options->cut_handles = false;
      break;
    default:  // a newer client's value
      return absl::InvalidArgumentError(absl::StrCat(
          "options.handles has unknown value ", proto.handles(),
          " (1 = HANDLE_TREATMENT_CUT, 2 = HANDLE_TREATMENT_KEEP)"));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<extract::Options> OptionsFromProto(
    const v1::ExtractOptions& proto, int max_threads) {
  extract::Options options;
  if (proto.bands() != 0) {
    if (!common::BandsInRange(proto.bands())) {
      return absl::InvalidArgumentError(
          absl::StrCat("options.bands must be in ", common::kMinBands, "..",
                       common::kMaxBands, " (0 for the default ",
                       extract::Options{}.bands, "), got ", proto.bands()));
    }
    options.bands = proto.bands();
  }
  if (proto.cycle_min_vertices() < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.cycle_min_vertices must be >= 0, got ",
                     proto.cycle_min_vertices()));
  }
  if (proto.cycle_min_vertices() != 0)
    options.cycle_min_vertices = proto.cycle_min_vertices();
  // The library would name its internal cycle_search_hops; the caller set
  // cycle_min_vertices, so name that and its range.
  if (options.cycle_min_vertices >= options.cycle_search_hops) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.cycle_min_vertices must be in [0, ",
                     options.cycle_search_hops - 1,
                     "] (cycles around a saddle are searched within ",
                     options.cycle_search_hops, " edges), got ",
                     proto.cycle_min_vertices()));
  }
  // The range rules refuse NaN.
  if (!common::RingLengthInRange(proto.ring_length_threshold())) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.ring_length_threshold must be in [0, 1), got ",
                     proto.ring_length_threshold()));
  }
  if (proto.ring_length_threshold() != 0.0) {
    options.ring_length_threshold = proto.ring_length_threshold();
  }
  if (proto.threads() < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.threads must be >= 0, got ", proto.threads()));
  }
  options.threads = std::clamp(proto.threads(), 1, std::max(1, max_threads));
  options.explain = proto.explain();
  if (!common::SpectrumEigenvaluesInRange(proto.spectrum_eigenvalues())) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.spectrum_eigenvalues must be in 1..",
                     common::kMaxSpectrumEigenvalues, " (0 for the default ",
                     extract::Options{}.spectrum_eigenvalues, "), got ",
                     proto.spectrum_eigenvalues()));
  }
  if (proto.spectrum_eigenvalues() != 0) {
    options.spectrum_eigenvalues = proto.spectrum_eigenvalues();
  }
  if (!common::ProminenceInRange(proto.point_min_prominence())) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.point_min_prominence must be in [0, 1], got ",
                     proto.point_min_prominence()));
  }
  if (proto.point_min_prominence() != 0.0) {
    options.point_min_prominence = proto.point_min_prominence();
  }
  if (!common::RingLengthInRange(proto.ring_min_length())) {
    return absl::InvalidArgumentError(
        absl::StrCat("options.ring_min_length must be in [0, 1), got ",
                     proto.ring_min_length()));
  }
  if (proto.ring_min_length() != 0.0) {
    options.ring_min_length = proto.ring_min_length();
  }
  TPR_RETURN_IF_ERROR(SetMethods(proto, &options));
  return options;
}

v1::ExtractOptions OptionsToProto(const extract::Options& options) {
  v1::ExtractOptions proto;
  proto.set_bands(options.bands);
  proto.set_cycle_min_vertices(options.cycle_min_vertices);
  proto.set_ring_length_threshold(options.ring_length_threshold);
  proto.set_threads(options.threads);
  proto.set_explain(options.explain);
  proto.set_spectrum_eigenvalues(options.spectrum_eigenvalues);
  proto.set_point_min_prominence(options.point_min_prominence);
  proto.set_handles(options.cut_handles ? v1::HANDLE_TREATMENT_CUT
                                        : v1::HANDLE_TREATMENT_KEEP);
  proto.set_topology(options.topology == extract::TopologyMethod::kPaper
                         ? v1::TOPOLOGY_METHOD_PAPER
                         : v1::TOPOLOGY_METHOD_PERSISTENCE);
  proto.set_ring_min_length(options.ring_min_length);
  return proto;
}

extract::MeshFormat FormatFromProto(v1::MeshFormat format) {
  switch (format) {
    case v1::MESH_FORMAT_OFF:
      return extract::MeshFormat::kOff;
    case v1::MESH_FORMAT_OBJ:
      return extract::MeshFormat::kObj;
    case v1::MESH_FORMAT_PLY:
      return extract::MeshFormat::kPly;
    case v1::MESH_FORMAT_STL:
      return extract::MeshFormat::kStl;
    default:
      return extract::MeshFormat::kUnknown;
  }
}

v1::MeshStats StatsToProto(const extract::MeshStats& stats) {
  v1::MeshStats proto;
  proto.set_vertices(stats.vertices);
  proto.set_faces(stats.faces);
  proto.set_area(stats.area);
  proto.set_boundary_edges(stats.boundary_edges);
  proto.set_components(stats.components);
  proto.set_genus(stats.genus);
  proto.set_dropped_degenerate_faces(stats.dropped_degenerate_faces);
  proto.set_dropped_duplicate_faces(stats.dropped_duplicate_faces);
  proto.set_unreferenced_vertices(stats.unreferenced_vertices);
  return proto;
}

v1::Signature SignatureToProto(const extract::Signature& signature,
                               const extract::Options& options) {
  v1::Signature proto;
  proto.mutable_features()->Reserve(
      static_cast<int>(signature.features.size()));
  for (const extract::Feature& f : signature.features) {
    v1::Feature* out = proto.add_features();
    out->set_kind(f.kind == extract::FeatureKind::kPoint
                      ? v1::FEATURE_KIND_POINT
                      : v1::FEATURE_KIND_RING);
    out->set_weight(f.weight);
    out->set_integral_geodesic(f.integral_geodesic);
    out->mutable_curvature()->Add(f.curvature.begin(), f.curvature.end());
    out->mutable_area()->Add(f.area.begin(), f.area.end());
    out->mutable_distance()->Add(f.distance.begin(), f.distance.end());
  }
  proto.mutable_spectrum()->Add(signature.spectrum.begin(),
                                signature.spectrum.end());
  *proto.mutable_mesh() = StatsToProto(signature.stats);
  proto.set_extractor_version(kExtractorVersion);
  proto.set_signature_version(kSignatureVersion);
  *proto.mutable_options() = OptionsToProto(options);
  return proto;
}

v1::Explanation ExplanationToProto(const extract::Explanation& explanation,
                                   const extract::Mesh& mesh) {
  v1::Explanation proto;
  proto.mutable_vertex_region()->Add(explanation.vertex_region.begin(),
                                     explanation.vertex_region.end());
  const int64_t n = static_cast<int64_t>(mesh.positions.size());
  for (const std::vector<int32_t>& vertices : explanation.feature_vertices) {
    v1::Explanation::FeatureVertices* out = proto.add_feature_vertices();
    out->mutable_vertices()->Add(vertices.begin(), vertices.end());
    out->mutable_positions()->Reserve(static_cast<int>(vertices.size() * 3));
    for (int32_t v : vertices) {
      if (v < 0 || v >= n) continue;
      for (int c = 0; c < 3; ++c) {
        out->add_positions(static_cast<float>(mesh.positions[v][c]));
      }
    }
  }
  return proto;
}

}  // namespace tpr::extractor
