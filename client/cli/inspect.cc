// `tpr inspect MESH -o OUT.ply`: the mesh coloured by TPR region, points red
// and rings black, as PLY for any viewer. The signature and its explanation
// come from tpr-extractor (ExtractOptions.explain); with --local they are
// computed in-process by the extractor library. Either way the mesh itself
// is read here, by the same intake as the server's, to write the colours on;
// this command is the only user of the extractor library in `tpr`.
#include <CLI/CLI.hpp>
#include <array>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/cli/cli_util.h"
#include "client/cli/command.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/lib/mesh_writer.h"

namespace tpr::cli {
namespace {

struct InspectFlags {
  std::string mesh;
  std::string out;
  int bands = 0;
  bool ascii = false;
  bool local = false;
};

// What inspect draws, wherever it was computed.
struct Drawing {
  std::vector<int32_t> vertex_region;
  std::vector<std::vector<int32_t>> feature_vertices;
  std::vector<bool> is_point;  // parallel to feature_vertices
  std::vector<std::string> warnings;
};

// Region colours: a fixed palette of light tones, so that the feature marks
// (saturated red for points, near-black for rings) stand out on any region.
extract::Rgb RegionColour(int region) {
  static const std::array<extract::Rgb, 12> kPalette = {{{166, 206, 227},
                                                         {178, 223, 138},
                                                         {251, 154, 153},
                                                         {253, 191, 111},
                                                         {202, 178, 214},
                                                         {255, 255, 153},
                                                         {141, 211, 199},
                                                         {190, 186, 218},
                                                         {128, 177, 211},
                                                         {179, 222, 105},
                                                         {252, 205, 229},
                                                         {217, 217, 217}}};
  if (region < 0) return {128, 128, 128};
  return kPalette[static_cast<size_t>(region) % kPalette.size()];
}

absl::StatusOr<Drawing> ExtractLocally(const extract::LoadedMesh& loaded,
                                       int bands) {
  extract::Options options;
  if (bands > 0) options.bands = bands;
  options.explain = true;
  options.threads = 2;
  absl::StatusOr<extract::ExtractResult> r =
      extract::ExtractSignature(loaded.mesh, loaded.stats, options);
  if (!r.ok()) return r.status();
  if (!r->explanation.has_value()) {
    return absl::InternalError("extraction returned no explanation");
  }
  Drawing d;
  d.vertex_region = std::move(r->explanation->vertex_region);
  d.feature_vertices = std::move(r->explanation->feature_vertices);
  for (const extract::Feature& f : r->signature.features) {
    d.is_point.push_back(f.kind == extract::FeatureKind::kPoint);
  }
  d.warnings = std::move(r->warnings);
  return d;
}

absl::StatusOr<Drawing> ExtractRemotely(const Globals& g,
                                        const std::string& path, int bands) {
  std::optional<tpr::client::ExtractorClient> client = ConnectExtractor(g);
  if (!client) return absl::InvalidArgumentError("bad --extractor address");
  tpr::v1::ExtractOptions options;
  options.set_bands(bands);
  options.set_explain(true);
  absl::StatusOr<tpr::v1::ExtractResponse> r =
      client->ExtractFile(path, options);
  if (!r.ok()) return r.status();
  Drawing d;
  const tpr::v1::Explanation& e = r->explanation();
  d.vertex_region.assign(e.vertex_region().begin(), e.vertex_region().end());
  for (const auto& f : e.feature_vertices()) {
    d.feature_vertices.emplace_back(f.vertices().begin(), f.vertices().end());
  }
  for (const tpr::v1::Feature& f : r->signature().features()) {
    d.is_point.push_back(f.kind() == tpr::v1::FEATURE_KIND_POINT);
  }
  d.warnings.assign(r->warnings().begin(), r->warnings().end());
  return d;
}

int RunInspect(const Globals& g, const InspectFlags& flags) {
  absl::StatusOr<extract::LoadedMesh> loaded =
      extract::LoadMeshFromFile(flags.mesh, extract::IntakeOptions{});
  if (!loaded.ok()) return Fail(flags.mesh, loaded.status());
  absl::StatusOr<Drawing> drawing =
      flags.local ? ExtractLocally(*loaded, flags.bands)
                  : ExtractRemotely(g, flags.mesh, flags.bands);
  if (!drawing.ok()) return Fail(flags.mesh, drawing.status());
  const extract::Mesh& mesh = loaded->mesh;
  const size_t n = mesh.positions.size();
  // Our intake and the server's must agree vertex for vertex; a server of
  // another version might not.
  if (drawing->vertex_region.size() != n ||
      drawing->feature_vertices.size() != drawing->is_point.size()) {
    return Fail(flags.mesh,
                absl::FailedPreconditionError(absl::StrCat(
                    "the explanation covers ", drawing->vertex_region.size(),
                    " vertices and ", drawing->feature_vertices.size(),
                    " features; the mesh read here has ", n,
                    " vertices (tpr and tpr-extractor versions differ? try "
                    "--local)")));
  }
  std::vector<extract::Rgb> colours(n);
  for (size_t v = 0; v < n; ++v) {
    colours[v] = RegionColour(drawing->vertex_region[v]);
  }
  int points = 0, rings = 0;
  for (size_t f = 0; f < drawing->feature_vertices.size(); ++f) {
    const bool is_point = drawing->is_point[f];
    (is_point ? points : rings)++;
    const extract::Rgb mark =
        is_point ? extract::Rgb{220, 20, 20} : extract::Rgb{20, 20, 20};
    for (int32_t v : drawing->feature_vertices[f]) {
      if (v < 0 || static_cast<size_t>(v) >= n) continue;
      colours[v] = mark;
      // A point is one vertex, too small to see: colour its one-ring too.
      if (!is_point) continue;
      for (const auto& t : mesh.triangles) {
        if (t[0] == v || t[1] == v || t[2] == v) {
          for (int32_t w : t) colours[w] = mark;
        }
      }
    }
  }
  extract::MeshWriteOptions write_options;
  write_options.format = flags.ascii ? extract::MeshWriteFormat::kPlyAscii
                                     : extract::MeshWriteFormat::kPlyBinary;
  write_options.vertex_colors = std::move(colours);
  absl::Status written =
      extract::WriteMeshToFile(mesh, write_options, flags.out);
  if (!written.ok()) return Fail(flags.out, written);
  if (g.json) {
    std::printf(
        "{\"file\":%s,\"out\":%s,\"points\":%d,\"rings\":%d,\"vertices\":%zu,"
        "\"local\":%s}\n",
        JsonString(flags.mesh).c_str(), JsonString(flags.out).c_str(), points,
        rings, n, flags.local ? "true" : "false");
  } else {
    std::printf(
        "%s: %d points (red), %d rings (black), regions in pastel -> "
        "%s\n",
        TextField(flags.mesh).c_str(), points, rings,
        TextField(flags.out).c_str());
    for (const std::string& w : drawing->warnings) {
      std::printf("  warning: %s\n", TextField(w).c_str());
    }
  }
  return 0;
}

const bool kRegistered = RegisterCommand(
    {"inspect",
     "write the mesh coloured by TPR region, points red and rings black, as "
     "PLY (extracted by tpr-extractor, or in-process with --local)",
     [](CLI::App& sub) {
       auto flags = std::make_shared<InspectFlags>();
       sub.add_option("MESH", flags->mesh, "mesh file")->required();
       sub.add_option("-o,--out", flags->out, "output PLY file")->required();
       sub.add_option("--bands", flags->bands,
                      "geodesic bands per feature (0: default)");
       sub.add_flag("--ascii", flags->ascii,
                    "write ASCII PLY (default binary)");
       sub.add_flag("--local", flags->local,
                    "extract in this process instead of through "
                    "tpr-extractor (no service needed)");
       return [flags](const Globals& g) { return RunInspect(g, *flags); };
     },
     "tpr inspect dog.off -o dog_regions.ply"});

}  // namespace
}  // namespace tpr::cli
