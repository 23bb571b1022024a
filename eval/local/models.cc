#include "eval/local/models.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <sstream>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/parallel.h"
#include "eval/lib/dataset.h"
#include "eval/lib/signature_cache.h"
#include "eval/lib/tpr_descriptor.h"
#include "extractor/lib/mesh_io.h"

namespace tpr::eval::local {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// The paper's invariance sets (section 7): rotated about one axis, randomly
// scaled in (1, 2], and rotated about another axis plus scaled.
void ApplyCopy(int copy, uint64_t seed, extract::Mesh* mesh) {
  if (copy == 0) return;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> angle(0.3, 2 * M_PI - 0.3);
  std::uniform_real_distribution<double> scale(1.0 + 1e-9, 2.0);
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  double s = 1.0;
  if (copy == 1)
    r = Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitZ())
            .toRotationMatrix();
  if (copy == 2) s = scale(rng);
  if (copy == 3) {
    r = Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitX())
            .toRotationMatrix();
    s = scale(rng);
  }
  for (Eigen::Vector3d& p : mesh->positions) p = s * (r * p);
}

// Bump whenever the extraction code changes what it produces, so that
// --cache never serves signatures of older feature code.
constexpr char kFeatureCodeVersion[] = "features-2026-11-30b";
// Bump whenever identity mode's skinning (extractor/synth) changes its
// meshes.
constexpr char kIdentitySkinVersion[] = "skinned-2026-11-30";

// CacheKey names everything a cached description depends on.
std::string CacheKey(const Model& model, const Config& config, size_t index) {
  std::ostringstream key;
  key << kFeatureCodeVersion << " copy=" << model.copy
      << " seed=" << config.seed
      << " copy_seed=" << config.seed * 1000003 + index;
  if (model.path.empty()) {
    key << " synth=" << model.label << "/" << model.synthetic_pose
        << " v=" << config.synthetic_vertices;
    // Re-polygonized identity meshes keep the key they had before the
    // skinned mode existed (the same meshes, synth_test pins them).
    if (model.identity_body >= 0 &&
        config.identity_surface == synth::IdentitySurface::kSkinned) {
      key << " identity_surface=" << kIdentitySkinVersion;
    }
  } else {
    std::error_code ec;
    key << " path="
        << fs::weakly_canonical(fs::absolute(model.path), ec).string()
        << " size=" << fs::file_size(model.path, ec);
  }
  const extract::Options& e = config.extract;
  key << " bands=" << e.bands << (e.bands_per_feature_extent ? "" : "/diameter")
      << " cycle=" << e.cycle_min_vertices << "/" << e.cycle_search_hops
      << " ring=" << e.ring_length_threshold << "/" << e.ring_min_length
      << " topology="
      << (e.topology == extract::TopologyMethod::kPaper ? "paper"
                                                        : "persistence")
      << " prominence=" << e.point_min_prominence
      << " stop=" << e.ring_stop_at_centre_saddles
      << (e.cut_handles ? " handles=cut" : "")
      << " spectrum=" << e.spectrum_eigenvalues << "/"
      << e.spectrum.max_vertices << "/" << e.spectrum.dense_max_vertices
      << " d2=" << config.d2.pairs << "/" << config.d2.bins << "/"
      << config.d2.range << "/" << config.d2.seed;
  return key.str();
}

// PrepareTpr sets out->tpr to the prepared form of out->raw and returns
// true, or sets out->error and returns false; the one step after both a
// cache hit and an extraction.
bool PrepareTpr(const Config& config, Described* out) {
  absl::StatusOr<index::PreparedSignature> prepared =
      index::Prepare(out->raw, config.ground);
  if (!prepared.ok()) {
    out->error = std::string(prepared.status().message());
    return false;
  }
  out->tpr = std::move(*prepared);
  return true;
}

}  // namespace

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start)
      .count();
}

absl::StatusOr<std::vector<Model>> ManifestModels(const std::string& manifest) {
  absl::StatusOr<std::vector<Item>> items = ReadDataset(manifest);
  if (!items.ok()) return items.status();
  std::vector<Model> models;
  for (Item& item : *items) {
    models.push_back(
        {std::move(item.id), std::move(item.label), std::move(item.path)});
  }
  return models;
}

absl::StatusOr<std::vector<Model>> SyntheticModels(const std::string& spec) {
  int classes = 8, poses = 10;
  const bool identity = spec.rfind("identity:", 0) == 0;
  const std::string dims = identity ? spec.substr(9) : spec;
  if (std::sscanf(dims.c_str(), "%dx%d", &classes, &poses) != 2 ||
      classes < 1 || poses < 1 ||
      (identity && classes > synth::kMaxIdentityBodies)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--synthetic takes CLASSESxPOSES (e.g. 8x10) or "
                     "identity:BODIESxPOSES; got '",
                     spec, "'"));
  }
  std::vector<std::string> names;
  if (identity) {
    for (int b = 0; b < classes; ++b)
      names.push_back(synth::IdentityBodyName(b));
  } else {
    names = synth::ClassNames();
  }
  classes = std::min<int>(classes, names.size());
  std::vector<Model> models;
  for (int c = 0; c < classes; ++c) {
    for (int p = 0; p < poses; ++p) {
      models.push_back({names[c] + "/" + std::to_string(p), names[c], "", p,
                        identity ? c : -1});
    }
  }
  return models;
}

Described Describe(const Model& model, const Config& config, size_t index) {
  Described out;
  std::string key;
  if (!config.cache_dir.empty()) {
    key = CacheKey(model, config, index);
    CachedDescription cached;
    if (LoadCached(config.cache_dir, key, &cached)) {
      out.raw = std::move(cached.signature);
      out.points = cached.points;
      out.rings = cached.rings;
      out.vertices = cached.vertices;
      out.faces = cached.faces;
      out.d2 = std::move(cached.d2);
      out.extract_ms = cached.extract_ms;
      out.stage_ms = std::move(cached.stage_ms);
      out.ok = PrepareTpr(config, &out);
      return out;
    }
  }
  absl::StatusOr<extract::LoadedMesh> loaded;
  if (model.path.empty()) {
    synth::ShapeOptions shape;
    shape.target_vertices = config.synthetic_vertices;
    shape.seed = config.seed;
    shape.identity_surface = config.identity_surface;
    absl::StatusOr<extract::Mesh> mesh =
        model.identity_body >= 0
            ? synth::GenerateIdentity(model.identity_body, model.synthetic_pose,
                                      shape)
            : synth::GenerateShape(model.label, model.synthetic_pose, shape);
    if (!mesh.ok()) {
      out.error = std::string(mesh.status().message());
      return out;
    }
    loaded = extract::BuildMesh(
        std::move(mesh->positions),
        [&] {
          std::vector<std::vector<int32_t>> polygons;
          for (const auto& t : mesh->triangles)
            polygons.push_back({t[0], t[1], t[2]});
          return polygons;
        }(),
        extract::IntakeOptions{});
  } else {
    loaded = extract::LoadMeshFromFile(model.path, extract::IntakeOptions{});
  }
  if (!loaded.ok()) {
    out.error = std::string(loaded.status().message());
    return out;
  }
  ApplyCopy(model.copy, config.seed * 1000003 + index, &loaded->mesh);
  const Clock::time_point start = Clock::now();
  absl::StatusOr<extract::ExtractResult> result =
      extract::ExtractSignature(loaded->mesh, loaded->stats, config.extract);
  out.extract_ms = MillisecondsSince(start);
  out.vertices = static_cast<int64_t>(loaded->mesh.positions.size());
  out.faces = static_cast<int64_t>(loaded->mesh.triangles.size());
  if (!result.ok()) {
    out.error = std::string(result.status().message());
    return out;
  }
  for (const extract::StageTiming& t : result->timings) {
    out.stage_ms[t.stage] += t.milliseconds;
  }
  for (const extract::Feature& f : result->signature.features) {
    (f.kind == extract::FeatureKind::kPoint ? out.points : out.rings) += 1;
  }
  absl::StatusOr<index::Signature> raw = ConvertSignature(result->signature);
  if (!raw.ok()) {
    out.error = std::string(raw.status().message());
    return out;
  }
  out.raw = *std::move(raw);
  if (!PrepareTpr(config, &out)) return out;
  out.d2 = D2Histogram(loaded->mesh, config.d2);
  out.ok = true;
  if (!key.empty()) {
    CachedDescription cached{out.raw,        out.points,  out.rings,
                             out.vertices,   out.faces,   out.d2,
                             out.extract_ms, out.stage_ms};
    if (!StoreCached(config.cache_dir, key, cached)) {
      std::fprintf(stderr, "warning: cannot write cache entry for %s\n",
                   model.name.c_str());
    }
  }
  return out;
}

std::vector<Described> DescribeAll(const std::vector<Model>& models,
                                   const Config& config, int threads) {
  std::fprintf(stderr, "describing %zu models on %d threads\n", models.size(),
               threads);
  std::vector<Described> described(models.size());
  std::atomic<int> done{0};
  const Clock::time_point start = Clock::now();
  common::ParallelFor(models.size(), threads, [&](size_t i) {
    described[i] = Describe(models[i], config, i);
    const int n = ++done;
    if (n % 20 == 0 || n == static_cast<int>(models.size())) {
      std::fprintf(stderr, "  %d/%zu (%.1f s)\n", n, models.size(),
                   MillisecondsSince(start) / 1000);
    }
  });
  return described;
}

}  // namespace tpr::eval::local
