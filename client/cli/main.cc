// tpr: the command-line tool of TPR Search, over the SDK (tpr/client.h).
//
//   tpr add shapes/                    # index a folder (labels from folders)
//   tpr query shapes/biped/pose_0.off -k 5
//   tpr inspect dog.off -o dog_regions.ply
//   tpr eval shapes/ --out results/     # retrieval quality (NN, FT, ST, ...)
//
// Addresses come from --extractor / --indexer or TPR_EXTRACTOR / TPR_INDEXER.
// Human output goes to stdout (progress and diagnostics to stderr); --json
// prints one JSON object per line. Exit code 0 on success, 1 when anything
// failed, 2 on bad usage.
#include <algorithm>
#include <array>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/add.h"
#include "client/cli/cli_util.h"
#include "client/cli/eval.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/lib/mesh_writer.h"
#include "tpr/client.h"

namespace {

using tpr::client::ExtractorClient;
using tpr::client::IndexerClient;

using tpr::cli::CallOptionsFor;
using tpr::cli::Fail;
using tpr::cli::Globals;
using tpr::cli::JsonString;
using tpr::cli::ToJson;

int CountKind(const tpr::v1::Signature& s, tpr::v1::FeatureKind kind) {
  return static_cast<int>(std::count_if(s.features().begin(), s.features().end(),
                                        [&](const tpr::v1::Feature& f) { return f.kind() == kind; }));
}

// --- extract -------------------------------------------------------------------

int RunExtract(const Globals& g, const std::vector<std::string>& meshes, int bands) {
  absl::StatusOr<ExtractorClient> client = ExtractorClient::Connect(g.extractor);
  if (!client.ok()) return Fail("--extractor", client.status());
  const tpr::client::CallOptions call = CallOptionsFor(g);
  tpr::v1::ExtractOptions options;
  options.set_bands(bands);
  int failures = 0;
  for (const std::string& path : meshes) {
    absl::StatusOr<tpr::v1::ExtractResponse> r = client->ExtractFile(path, options, &call);
    if (!r.ok()) {
      ++failures;
      if (g.json) {
        std::printf("{\"file\":%s,\"error\":%s}\n", JsonString(path).c_str(),
                    JsonString(r.status().ToString()).c_str());
      } else {
        Fail(path, r.status());
      }
      continue;
    }
    if (g.json) {
      std::printf("{\"file\":%s,\"response\":%s}\n", JsonString(path).c_str(),
                  ToJson(*r).c_str());
      continue;
    }
    const tpr::v1::Signature& s = r->signature();
    double total = 0;
    std::string stages;
    for (const tpr::v1::StageTiming& t : r->timings()) {
      total += t.milliseconds();
      absl::StrAppend(&stages, stages.empty() ? "" : ", ", t.stage(), " ",
                      absl::StrFormat("%.1f", t.milliseconds()));
    }
    std::printf("%s: %d points, %d rings (%lld vertices, %lld faces, genus %lld); %.1f ms "
                "[%s]\n",
                path.c_str(), CountKind(s, tpr::v1::FEATURE_KIND_POINT),
                CountKind(s, tpr::v1::FEATURE_KIND_RING),
                static_cast<long long>(s.mesh().vertices()),
                static_cast<long long>(s.mesh().faces()),
                static_cast<long long>(s.mesh().genus()), total, stages.c_str());
    for (const std::string& w : r->warnings()) std::printf("  warning: %s\n", w.c_str());
  }
  return failures == 0 ? 0 : 1;
}

// --- query ---------------------------------------------------------------------

int RunQuery(const Globals& g, const std::string& mesh, const std::string& id, int k,
             double radius, const std::string& label, bool exclude_self) {
  if (mesh.empty() == id.empty()) {
    std::fprintf(stderr, "tpr query: give either MESH or --id ID\n");
    return 2;
  }
  absl::StatusOr<IndexerClient> indexer = IndexerClient::Connect(g.indexer);
  if (!indexer.ok()) return Fail("--indexer", indexer.status());
  const tpr::client::CallOptions call = CallOptionsFor(g);
  tpr::v1::SearchRequest request;
  if (!mesh.empty()) {
    absl::StatusOr<ExtractorClient> extractor = ExtractorClient::Connect(g.extractor);
    if (!extractor.ok()) return Fail("--extractor", extractor.status());
    absl::StatusOr<tpr::v1::ExtractResponse> r = extractor->ExtractFile(mesh, {}, &call);
    if (!r.ok()) return Fail(mesh, r.status());
    *request.mutable_signature() = std::move(*r->mutable_signature());
  } else {
    request.set_id(id);
    request.set_exclude_self(exclude_self);
  }
  request.set_k(k);
  request.set_radius(radius);
  request.set_label(label);
  std::unique_ptr<tpr::client::SearchStream> stream = indexer->Search(request, &call);
  tpr::v1::Neighbor n;
  bool header = false;
  while (stream->Next(&n)) {
    if (g.json) {
      std::printf("{\"rank\":%d,\"id\":%s,\"label\":%s,\"distance\":%.17g}\n", n.rank(),
                  JsonString(n.id()).c_str(), JsonString(n.label()).c_str(), n.distance());
    } else {
      if (!header) std::printf("%4s  %-40s %-20s %s\n", "rank", "id", "label", "distance");
      header = true;
      std::printf("%4d  %-40s %-20s %.6f\n", n.rank(), n.id().c_str(), n.label().c_str(),
                  n.distance());
    }
    std::fflush(stdout);  // show each neighbour as it arrives
  }
  absl::Status status = stream->Finish();
  if (!status.ok()) return Fail("query", status);
  if (!g.json && stream->Stats() != nullptr) {
    const tpr::v1::SearchStats& s = *stream->Stats();
    std::fprintf(stderr, "(%lld EMDs, %lld lower bounds, %lld nodes, %.2f ms on the server)\n",
                 static_cast<long long>(s.emd_computations()),
                 static_cast<long long>(s.lower_bounds()),
                 static_cast<long long>(s.nodes_visited()), s.milliseconds());
  }
  return 0;
}

// --- get / remove / list / stats -------------------------------------------------

int RunGet(const Globals& g, const std::vector<std::string>& ids) {
  absl::StatusOr<IndexerClient> indexer = IndexerClient::Connect(g.indexer);
  if (!indexer.ok()) return Fail("--indexer", indexer.status());
  const tpr::client::CallOptions call = CallOptionsFor(g);
  int failures = 0;
  for (const std::string& id : ids) {
    absl::StatusOr<tpr::v1::Model> m = indexer->Get(id, &call);
    if (!m.ok()) {
      ++failures;
      Fail(id, m.status());
      continue;
    }
    if (g.json) {
      std::printf("%s\n", ToJson(*m).c_str());
      continue;
    }
    const tpr::v1::Signature& s = m->signature();
    const absl::Time added = absl::FromUnixMicros(m->added_unix_micros());
    std::printf("id:       %s\nlabel:    %s\nadded:    %s\nfeatures: %d points, %d rings "
                "(%d bands)\nmesh:     %lld vertices, %lld faces, genus %lld, %lld "
                "components\nversion:  %s\n",
                m->id().c_str(), m->label().c_str(),
                absl::FormatTime("%Y-%m-%d %H:%M:%S UTC", added, absl::UTCTimeZone()).c_str(),
                CountKind(s, tpr::v1::FEATURE_KIND_POINT), CountKind(s, tpr::v1::FEATURE_KIND_RING),
                s.options().bands(), static_cast<long long>(s.mesh().vertices()),
                static_cast<long long>(s.mesh().faces()),
                static_cast<long long>(s.mesh().genus()),
                static_cast<long long>(s.mesh().components()), s.extractor_version().c_str());
    for (const auto& [key, value] : m->metadata()) {
      std::printf("meta:     %s = %s\n", key.c_str(), value.c_str());
    }
  }
  return failures == 0 ? 0 : 1;
}

int RunRemove(const Globals& g, const std::vector<std::string>& ids) {
  absl::StatusOr<IndexerClient> indexer = IndexerClient::Connect(g.indexer);
  if (!indexer.ok()) return Fail("--indexer", indexer.status());
  const tpr::client::CallOptions call = CallOptionsFor(g);
  int failures = 0;
  for (const std::string& id : ids) {
    absl::Status s = indexer->Delete(id, &call);
    if (!s.ok()) {
      ++failures;
      Fail(id, s);
    } else if (g.json) {
      std::printf("{\"removed\":%s}\n", JsonString(id).c_str());
    } else {
      std::printf("removed %s\n", id.c_str());
    }
  }
  return failures == 0 ? 0 : 1;
}

int RunList(const Globals& g, const std::string& label) {
  absl::StatusOr<IndexerClient> indexer = IndexerClient::Connect(g.indexer);
  if (!indexer.ok()) return Fail("--indexer", indexer.status());
  const tpr::client::CallOptions call = CallOptionsFor(g);
  absl::StatusOr<std::vector<tpr::v1::Model>> models = indexer->ListAll(label, &call);
  if (!models.ok()) return Fail("list", models.status());
  for (const tpr::v1::Model& m : *models) {
    if (g.json) {
      std::printf("{\"id\":%s,\"label\":%s,\"added_unix_micros\":%lld}\n",
                  JsonString(m.id()).c_str(), JsonString(m.label()).c_str(),
                  static_cast<long long>(m.added_unix_micros()));
    } else {
      std::printf("%-48s %s\n", m.id().c_str(), m.label().c_str());
    }
  }
  if (!g.json) std::fprintf(stderr, "(%zu models)\n", models->size());
  return 0;
}

int RunStats(const Globals& g) {
  absl::StatusOr<IndexerClient> indexer = IndexerClient::Connect(g.indexer);
  if (!indexer.ok()) return Fail("--indexer", indexer.status());
  const tpr::client::CallOptions call = CallOptionsFor(g);
  absl::StatusOr<tpr::v1::StatsResponse> s = indexer->Stats(&call);
  if (!s.ok()) return Fail("stats", s.status());
  if (g.json) {
    std::printf("%s\n", ToJson(*s).c_str());
    return 0;
  }
  std::printf("models:   %lld (%lld in the VP-tree, %lld buffered)\ndisk:     %.1f MiB\n",
              static_cast<long long>(s->models()), static_cast<long long>(s->indexed()),
              static_cast<long long>(s->buffered()), s->disk_bytes() / 1048576.0);
  std::map<std::string, int64_t> labels(s->labels().begin(), s->labels().end());
  for (const auto& [label, count] : labels) {
    std::printf("label:    %-24s %lld\n", label.empty() ? "(none)" : label.c_str(),
                static_cast<long long>(count));
  }
  return 0;
}

// --- inspect -------------------------------------------------------------------

// Region colours: a fixed palette of light tones, so that the feature marks
// (saturated red for points, near-black for rings) stand out on any region.
std::array<uint8_t, 3> RegionColour(int region) {
  static const std::array<std::array<uint8_t, 3>, 12> kPalette = {{
      {166, 206, 227}, {178, 223, 138}, {251, 154, 153}, {253, 191, 111},
      {202, 178, 214}, {255, 255, 153}, {141, 211, 199}, {190, 186, 218},
      {128, 177, 211}, {179, 222, 105}, {252, 205, 229}, {217, 217, 217}}};
  if (region < 0) return {128, 128, 128};
  return kPalette[static_cast<size_t>(region) % kPalette.size()];
}

int RunInspect(const Globals& g, const std::string& mesh_path, const std::string& out,
               int bands, bool ascii) {
  tpr::extract::IntakeOptions intake;
  absl::StatusOr<tpr::extract::LoadedMesh> loaded = tpr::extract::LoadMeshFromFile(mesh_path, intake);
  if (!loaded.ok()) return Fail(mesh_path, loaded.status());
  tpr::extract::Options options;
  if (bands > 0) options.bands = bands;
  options.explain = true;
  options.threads = 2;
  absl::StatusOr<tpr::extract::ExtractResult> r =
      tpr::extract::ExtractSignature(loaded->mesh, loaded->stats, options);
  if (!r.ok()) return Fail(mesh_path, r.status());
  if (!r->explanation.has_value()) {
    return Fail(mesh_path, absl::InternalError("extraction returned no explanation"));
  }
  const tpr::extract::Explanation& e = *r->explanation;
  const size_t n = loaded->mesh.positions.size();
  std::vector<tpr::extract::Rgb> colours(n, tpr::extract::Rgb{128, 128, 128});
  for (size_t v = 0; v < n && v < e.vertex_region.size(); ++v) {
    colours[v] = RegionColour(e.vertex_region[v]);
  }
  int points = 0, rings = 0;
  const auto& features = r->signature.features;
  for (size_t f = 0; f < features.size() && f < e.feature_vertices.size(); ++f) {
    const bool is_point = features[f].kind == tpr::extract::FeatureKind::kPoint;
    (is_point ? points : rings)++;
    const std::array<uint8_t, 3> mark =
        is_point ? std::array<uint8_t, 3>{220, 20, 20} : std::array<uint8_t, 3>{20, 20, 20};
    for (int32_t v : e.feature_vertices[f]) {
      if (v < 0 || static_cast<size_t>(v) >= n) continue;
      colours[v] = mark;
      // A point is one vertex, too small to see: colour its one-ring too.
      if (is_point) {
        for (const auto& t : loaded->mesh.triangles) {
          if (t[0] == v || t[1] == v || t[2] == v) {
            for (int32_t w : t) colours[w] = mark;
          }
        }
      }
    }
  }
  tpr::extract::MeshWriteOptions write_options;
  write_options.format =
      ascii ? tpr::extract::MeshWriteFormat::kPlyAscii : tpr::extract::MeshWriteFormat::kPlyBinary;
  write_options.vertex_colors = std::move(colours);
  absl::Status written = tpr::extract::WriteMeshToFile(loaded->mesh, write_options, out);
  if (!written.ok()) return Fail(out, written);
  if (g.json) {
    std::printf("{\"file\":%s,\"out\":%s,\"points\":%d,\"rings\":%d,\"vertices\":%zu}\n",
                JsonString(mesh_path).c_str(), JsonString(out).c_str(), points, rings, n);
  } else {
    std::printf("%s: %d points (red), %d rings (black), regions in pastel -> %s\n",
                mesh_path.c_str(), points, rings, out.c_str());
    for (const std::string& w : r->warnings) std::printf("  warning: %s\n", w.c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Globals g;
  CLI::App app{"tpr: TPR Search command-line tool (deformable 3D model retrieval)"};
  app.require_subcommand(1);
  app.fallthrough();
  app.add_option("--extractor", g.extractor, "tpr-extractor address(es), HOST:PORT[,HOST:PORT]")
      ->envname("TPR_EXTRACTOR")
      ->capture_default_str();
  app.add_option("--indexer", g.indexer, "tpr-indexer address(es), HOST:PORT[,HOST:PORT]")
      ->envname("TPR_INDEXER")
      ->capture_default_str();
  app.add_flag("--json", g.json, "machine output: one JSON object per line");
  app.add_option("--timeout", g.timeout_s, "deadline per call, in seconds")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);

  std::vector<std::string> extract_meshes;
  int bands = 0;
  CLI::App* extract = app.add_subcommand("extract", "print the signature summary of meshes");
  extract->add_option("MESH", extract_meshes, "mesh files (OFF, OBJ, PLY, STL)")->required();
  extract->add_option("--bands", bands, "geodesic bands per feature (0: default 20)");

  std::vector<std::string> add_paths;
  std::string manifest;
  tpr::cli::AddOptions add_options;
  CLI::App* add = app.add_subcommand(
      "add", "index mesh files or folders (recursive); ids are paths relative to the folder "
             "given (a file argument: its path as given), labels the parent folder names "
             "(or --manifest)");
  add->add_option("PATH", add_paths, "mesh files or folders")->required();
  add->add_option("--manifest", manifest, "file of 'RELATIVE/PATH LABEL' lines");
  add->add_option("--jobs,-j", add_options.jobs, "parallel uploads")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  add->add_flag("--update", add_options.update, "replace ids already present (default: skip them)");

  std::string query_mesh, query_id, query_label;
  int k = 10;
  double radius = 0;
  bool exclude_self = false;
  CLI::App* query = app.add_subcommand("query", "k nearest models to a mesh or a stored id");
  query->add_option("MESH", query_mesh, "query mesh file");
  query->add_option("--id", query_id, "query by stored model id instead of a mesh");
  query->add_option("-k", k, "number of neighbours")->capture_default_str();
  query->add_option("--radius", radius, "only neighbours at distance <= radius (0: any)");
  query->add_option("--label", query_label, "only models with this label");
  query->add_flag("--exclude-self", exclude_self, "with --id, leave the query model out");

  std::vector<std::string> get_ids;
  CLI::App* get = app.add_subcommand("get", "show stored models");
  get->add_option("ID", get_ids, "model ids")->required();

  std::vector<std::string> remove_ids;
  CLI::App* remove = app.add_subcommand("remove", "delete stored models");
  remove->add_option("ID", remove_ids, "model ids")->required();

  std::string list_label;
  CLI::App* list = app.add_subcommand("list", "list stored models in id order");
  list->add_option("--label", list_label, "only models with this label");

  CLI::App* stats = app.add_subcommand("stats", "index counts and sizes");

  std::string inspect_mesh, inspect_out;
  int inspect_bands = 0;
  CLI::App* inspect = app.add_subcommand(
      "inspect", "extract locally and write the mesh coloured by TPR region, points red and "
                 "rings black, as PLY");
  inspect->add_option("MESH", inspect_mesh, "mesh file")->required();
  inspect->add_option("-o,--out", inspect_out, "output PLY file")->required();
  inspect->add_option("--bands", inspect_bands, "geodesic bands per feature (0: default)");
  bool inspect_ascii = false;
  inspect->add_flag("--ascii", inspect_ascii, "write ASCII PLY (default binary)");

  std::string eval_dataset;
  tpr::cli::EvalOptions eval_options;
  CLI::App* eval = app.add_subcommand(
      "eval", "retrieval quality of a labelled set through the services: extract and index "
              "every model (as add), query each by id against all others, print NN, FT, ST, "
              "E, DCG and mAP per class and overall, and draw the precision-recall curve and "
              "the mean class-similarity matrix (SVG)");
  eval->add_option("DATASET", eval_dataset,
                   "folder of class subfolders, or manifest file of 'PATH CLASS' lines (paths "
                   "relative to it)")
      ->required();
  eval->add_option("--out,-o", eval_options.out_dir,
                   "folder for precision_recall.svg and similarity.svg")
      ->capture_default_str();
  eval->add_option("--jobs,-j", eval_options.add.jobs, "parallel uploads and queries")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  eval->add_flag("--update", eval_options.add.update,
                 "re-extract ids already in the indexer (default: use them as they are)");

  CLI11_PARSE(app, argc, argv);

  if (*extract) return RunExtract(g, extract_meshes, bands);
  if (*add) return tpr::cli::RunAdd(g, add_paths, manifest, add_options);
  if (*query) return RunQuery(g, query_mesh, query_id, k, radius, query_label, exclude_self);
  if (*get) return RunGet(g, get_ids);
  if (*remove) return RunRemove(g, remove_ids);
  if (*list) return RunList(g, list_label);
  if (*stats) return RunStats(g);
  if (*inspect) return RunInspect(g, inspect_mesh, inspect_out, inspect_bands, inspect_ascii);
  if (*eval) return tpr::cli::RunEval(g, eval_dataset, eval_options);
  return 2;
}
