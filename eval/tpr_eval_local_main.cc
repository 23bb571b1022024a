// tpr-eval-local: in-process retrieval evaluation for research and tuning.
// Links the pure libraries directly (no services), extracts every model once,
// computes the full leave-one-out distance matrix for each descriptor (TPR
// under the EMD, and the D2 baseline) and prints PSB/SHREC metrics, per class
// and overall, with SVG pictures. `tpr eval` does the same through the
// services.
//
//   tpr-eval-local --out results/ --invariance
//       --manifest ../shared/data/shrec07-watertight/MANIFEST.txt
//   tpr-eval-local --synthetic 8x10 --out /tmp/eval
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>

#include "eval/lib/d2.h"
#include "eval/lib/metrics.h"
#include "eval/lib/plots.h"
#include "eval/lib/signature_cache.h"
#include "eval/lib/tpr_descriptor.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/synth/synth.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/signature_index.h"

namespace tpr::eval {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start)
      .count();
}

// A model of the evaluation set: where it came from and its class.
struct Model {
  std::string name;
  std::string label;
  std::string path;       // empty for synthetic models
  int synthetic_pose = -1;
  int copy = 0;           // 0 original; 1..3 the paper's invariance copies
};

// What one model contributes to each descriptor.
struct Described {
  bool ok = false;
  std::string error;
  index::Signature raw;
  index::PreparedSignature tpr;
  int points = 0, rings = 0;
  int64_t vertices = 0, faces = 0;
  std::vector<double> d2;
  double extract_ms = 0.0;
  std::map<std::string, double> stage_ms;
};

// The paper's invariance sets (section 7): rotated about one axis, randomly
// scaled in (1, 2], and rotated about another axis plus scaled.
void ApplyCopy(int copy, uint64_t seed, extract::Mesh* mesh) {
  if (copy == 0) return;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> angle(0.3, 2 * M_PI - 0.3);
  std::uniform_real_distribution<double> scale(1.0 + 1e-9, 2.0);
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  double s = 1.0;
  if (copy == 1) r = Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  if (copy == 2) s = scale(rng);
  if (copy == 3) {
    r = Eigen::AngleAxisd(angle(rng), Eigen::Vector3d::UnitX()).toRotationMatrix();
    s = scale(rng);
  }
  for (Eigen::Vector3d& p : mesh->positions) p = s * (r * p);
}

std::vector<Model> ReadManifest(const std::string& manifest) {
  std::vector<Model> models;
  std::ifstream in(manifest);
  if (!in) {
    std::cerr << "cannot open manifest " << manifest << "\n";
    std::exit(2);
  }
  const fs::path root = fs::path(manifest).parent_path();
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string rel, label;
    if (!(fields >> rel >> label)) continue;
    models.push_back({rel, label, (root / rel).string()});
  }
  return models;
}

std::vector<Model> SyntheticModels(const std::string& spec) {
  int classes = 8, poses = 10;
  if (std::sscanf(spec.c_str(), "%dx%d", &classes, &poses) != 2) {
    std::cerr << "--synthetic takes CLASSESxPOSES, e.g. 8x10\n";
    std::exit(2);
  }
  std::vector<std::string> names = synth::ClassNames();
  classes = std::min<int>(classes, names.size());
  std::vector<Model> models;
  for (int c = 0; c < classes; ++c) {
    for (int p = 0; p < poses; ++p) {
      models.push_back({names[c] + "/" + std::to_string(p), names[c], "", p});
    }
  }
  return models;
}

struct Config {
  extract::Options extract;
  index::GroundDistanceOptions ground;
  D2Options d2;
  int synthetic_vertices = 5000;
  uint64_t seed = 1;
  std::string cache_dir;  // empty: no cache
};

// Bump whenever the extraction code changes what it produces, so that
// --cache never serves signatures of older feature code.
constexpr char kFeatureCodeVersion[] = "features-2026-11-22b";

// CacheKey names everything a cached description depends on.
std::string CacheKey(const Model& model, const Config& config, size_t index) {
  std::ostringstream key;
  key << kFeatureCodeVersion << " copy=" << model.copy << " seed=" << config.seed
      << " copy_seed=" << config.seed * 1000003 + index;
  if (model.path.empty()) {
    key << " synth=" << model.label << "/" << model.synthetic_pose
        << " v=" << config.synthetic_vertices;
  } else {
    std::error_code ec;
    key << " path=" << fs::weakly_canonical(fs::absolute(model.path), ec).string()
        << " size=" << fs::file_size(model.path, ec);
  }
  const extract::Options& e = config.extract;
  key << " bands=" << e.bands << (e.bands_per_feature_extent ? "" : "/diameter") << " cycle=" << e.cycle_min_vertices << "/"
      << e.cycle_search_hops << " ring=" << e.ring_length_threshold
      << " stop=" << e.ring_stop_at_centre_saddles << " d2=" << config.d2.pairs << "/"
      << config.d2.bins << "/" << config.d2.range << "/" << config.d2.seed;
  return key.str();
}

// Vertex and face counts from an OFF file's header, for cache entries of
// format v1 that did not record them; (0, 0) for other formats.
std::pair<int64_t, int64_t> OffHeaderCounts(const std::string& path) {
  std::ifstream in(path);
  std::string token;
  if (!(in >> token) || token.rfind("OFF", 0) != 0) return {0, 0};
  int64_t v = 0, f = 0;
  if (token.size() > 3) {  // "OFF" glued to nothing else is the usual case
    return {0, 0};
  }
  if (!(in >> v >> f)) return {0, 0};
  return {v, f};
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
      if (out.vertices == 0 && !model.path.empty()) {
        std::tie(out.vertices, out.faces) = OffHeaderCounts(model.path);
      }
      out.d2 = std::move(cached.d2);
      out.extract_ms = cached.extract_ms;
      out.stage_ms = std::move(cached.stage_ms);
      absl::StatusOr<index::PreparedSignature> prepared = index::Prepare(out.raw, config.ground);
      if (!prepared.ok()) {
        out.error = std::string(prepared.status().message());
        return out;
      }
      out.tpr = std::move(*prepared);
      out.ok = true;
      return out;
    }
  }
  absl::StatusOr<extract::LoadedMesh> loaded;
  if (model.path.empty()) {
    synth::ShapeOptions shape;
    shape.target_vertices = config.synthetic_vertices;
    shape.seed = config.seed;
    absl::StatusOr<extract::Mesh> mesh =
        synth::GenerateShape(model.label, model.synthetic_pose, shape);
    if (!mesh.ok()) {
      out.error = std::string(mesh.status().message());
      return out;
    }
    loaded = extract::BuildMesh(
        std::move(mesh->positions),
        [&] {
          std::vector<std::vector<int32_t>> polygons;
          for (const auto& t : mesh->triangles) polygons.push_back({t[0], t[1], t[2]});
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
  out.raw = ToIndexSignature(result->signature);
  absl::StatusOr<index::PreparedSignature> prepared =
      index::Prepare(out.raw, config.ground);
  if (!prepared.ok()) {
    out.error = std::string(prepared.status().message());
    return out;
  }
  out.tpr = std::move(*prepared);
  out.d2 = D2Histogram(loaded->mesh, config.d2);
  out.ok = true;
  if (!key.empty()) {
    CachedDescription cached{out.raw,    out.points,     out.rings,   out.vertices,
                             out.faces,  out.d2,         out.extract_ms, out.stage_ms};
    if (!StoreCached(config.cache_dir, key, cached)) {
      std::fprintf(stderr, "warning: cannot write cache entry for %s\n", model.name.c_str());
    }
  }
  return out;
}

// Runs fn(i) for i in [0, n) on `threads` threads.
template <typename Fn>
void ParallelFor(size_t n, int threads, Fn fn) {
  std::atomic<size_t> next{0};
  std::vector<std::thread> pool;
  for (int t = 0; t < std::max(1, threads); ++t) {
    pool.emplace_back([&] {
      for (size_t i = next++; i < n; i = next++) fn(i);
    });
  }
  for (std::thread& t : pool) t.join();
}

using Matrix = std::vector<std::vector<double>>;

// Leave-one-out queries over the models in `subset` (indices into the
// matrix), as Query objects indexed within the subset.
std::vector<Query> QueriesFor(const Matrix& d, const std::vector<int>& subset) {
  std::vector<Query> queries;
  for (size_t qi = 0; qi < subset.size(); ++qi) {
    Query q{static_cast<int>(qi), {}};
    for (size_t mi = 0; mi < subset.size(); ++mi) {
      if (mi != qi) q.ranking.push_back({static_cast<int>(mi), d[subset[qi]][subset[mi]]});
    }
    queries.push_back(std::move(q));
  }
  return queries;
}

double Objective(const Metrics& m) { return (m.nn + m.ft + m.st + m.dcg) / 4; }

std::string MetricsJson(const Metrics& m) {
  char buf[256];
  std::snprintf(buf, sizeof(buf),
                "{\"queries\": %d, \"nn\": %.4f, \"ft\": %.4f, \"st\": %.4f, "
                "\"e\": %.4f, \"dcg\": %.4f, \"map\": %.4f}",
                m.queries, m.nn, m.ft, m.st, m.e, m.dcg, m.map);
  return buf;
}

void PrintTable(const std::string& name, const Scores& s) {
  std::printf("\n%s\n%-18s %6s %6s %6s %6s %6s %6s %6s\n", name.c_str(), "class",
              "models", "NN", "FT", "ST", "E", "DCG", "mAP");
  auto row = [](const std::string& cls, const Metrics& m) {
    std::printf("%-18s %6d %6.3f %6.3f %6.3f %6.3f %6.3f %6.3f\n", cls.c_str(),
                m.queries, m.nn, m.ft, m.st, m.e, m.dcg, m.map);
  };
  for (const auto& [cls, m] : s.per_class) row(cls, m);
  row("ALL", s.overall);
}

std::string MarkdownScores(const std::string& title, const Scores& s) {
  std::string out = "#### " + title + "\n\n| class | models | NN | FT | ST | E | DCG | mAP |\n"
                    "|---|---:|---:|---:|---:|---:|---:|---:|\n";
  char buf[200];
  auto row = [&](const std::string& cls, const Metrics& m) {
    std::snprintf(buf, sizeof(buf), "| %s | %d | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f |\n",
                  cls.c_str(), m.queries, m.nn, m.ft, m.st, m.e, m.dcg, m.map);
    out += buf;
  };
  for (const auto& [cls, m] : s.per_class) row(cls, m);
  row("**all**", s.overall);
  return out + "\n";
}

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

int Run(int argc, char** argv) {
  CLI::App app{"In-process TPR retrieval evaluation (PSB/SHREC metrics)"};
  std::string manifest, synthetic, out_dir;
  bool invariance = false, tune = false, index_timing = false;
  int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  Config config;
  app.add_option("--manifest", manifest, "MANIFEST.txt: '<relative path> <class>' per line");
  app.add_option("--synthetic", synthetic, "generate CLASSESxPOSES synthetic models instead");
  app.add_option("--synthetic-vertices", config.synthetic_vertices, "vertices per synthetic model");
  app.add_option("--out", out_dir, "folder for results.json and SVG pictures");
  app.add_flag("--invariance", invariance,
               "add rotated, scaled and rotated+scaled copies (the paper's 4x database)");
  app.add_flag("--tune", tune,
               "cross-validate W1..W4 on half of each class, report on the other half");
  app.add_option("--threads", threads, "worker threads");
  app.add_flag("--index-timing", index_timing,
               "also time k-NN queries through the VP-tree index (paper Table 7)");
  app.add_option("--bands", config.extract.bands, "geodesic bands (5.3)");
  app.add_option("--band-extent", config.extract.bands_per_feature_extent,
                 "bands span each feature's own extent (1) or the mesh's geodesic diameter (0)");
  app.add_option("--ring-threshold", config.extract.ring_length_threshold, "ring length threshold (4.6.2)");
  app.add_option("--w1", config.ground.w1, "Eq. 7 weight of G'");
  app.add_option("--w2", config.ground.w2, "Eq. 7 weight of curvature");
  app.add_option("--w3", config.ground.w3, "Eq. 7 weight of area");
  app.add_option("--w4", config.ground.w4, "Eq. 7 weight of thickness");
  app.add_option("--seed", config.seed, "seed for copies, D2 and synthetic shapes");
  app.add_option("--cache", config.cache_dir,
                 "folder caching extracted signatures (keyed by mesh, copy and options)");
  app.add_option("--k-scale", config.ground.k_scale, "Eq. 7 L2norm scale of curvature");
  app.add_option("--a-scale", config.ground.a_scale, "Eq. 7 L2norm scale of area");
  app.add_option("--h-scale", config.ground.h_scale, "Eq. 7 L2norm scale of thickness");
  std::string dump;
  app.add_option("--dump", dump, "write every model's features (text) to this file");
  CLI11_PARSE(app, argc, argv);
  if (manifest.empty() == synthetic.empty()) {
    std::cerr << "give exactly one of --manifest or --synthetic\n";
    return 2;
  }
  config.d2.seed = config.seed;

  std::vector<Model> base = manifest.empty() ? SyntheticModels(synthetic)
                                             : ReadManifest(manifest);
  std::vector<Model> models = base;
  if (invariance) {
    for (int copy = 1; copy <= 3; ++copy) {
      for (Model m : base) {
        m.copy = copy;
        m.name += "#" + std::to_string(copy);
        models.push_back(m);
      }
    }
  }
  std::fprintf(stderr, "describing %zu models on %d threads\n", models.size(), threads);
  std::vector<Described> described(models.size());
  std::atomic<int> done{0};
  const Clock::time_point start = Clock::now();
  ParallelFor(models.size(), threads, [&](size_t i) {
    described[i] = Describe(models[i], config, i);
    const int n = ++done;
    if (n % 20 == 0 || n == static_cast<int>(models.size())) {
      std::fprintf(stderr, "  %d/%zu (%.1f s)\n", n, models.size(), MillisecondsSince(start) / 1000);
    }
  });

  // Failed models are reported and left out (they cannot be ranked).
  std::vector<int> kept;
  std::map<std::string, std::pair<int, int>> features_per_class;  // points, rings
  std::map<std::string, int> models_per_class;
  double extract_ms = 0.0;
  int64_t sum_vertices = 0, sum_faces = 0;
  std::map<std::string, double> stage_ms;
  for (size_t i = 0; i < models.size(); ++i) {
    if (!described[i].ok) {
      std::fprintf(stderr, "FAILED %s: %s\n", models[i].name.c_str(), described[i].error.c_str());
      continue;
    }
    kept.push_back(static_cast<int>(i));
    auto& fc = features_per_class[models[i].label];
    fc.first += described[i].points;
    fc.second += described[i].rings;
    models_per_class[models[i].label] += 1;
    extract_ms += described[i].extract_ms;
    sum_vertices += described[i].vertices;
    sum_faces += described[i].faces;
    for (const auto& [stage, ms] : described[i].stage_ms) stage_ms[stage] += ms;
  }
  if (kept.size() < 2) {
    std::cerr << "fewer than two models described; nothing to evaluate\n";
    return 1;
  }
  std::printf("models %zu described, %zu failed; mean extraction %.1f ms\n", kept.size(),
              models.size() - kept.size(), extract_ms / kept.size());
  for (const auto& [stage, ms] : stage_ms) {
    std::printf("  stage %-18s %8.2f ms\n", stage.c_str(), ms / kept.size());
  }
  std::printf("%-18s %8s %8s\n", "class", "points", "rings");
  for (const auto& [cls, pr] : features_per_class) {
    const double n = models_per_class[cls];
    std::printf("%-18s %8.2f %8.2f\n", cls.c_str(), pr.first / n, pr.second / n);
  }

  // Balance of the Eq. 7 terms: the mean unweighted, scaled contribution
  // of each block over feature pairs of different models (weighted by the
  // features' masses, as the EMD sees them).
  {
    auto l2 = [](const std::vector<double>& x, const std::vector<double>& y) {
      double s = 0.0;
      for (size_t b = 0; b < x.size() && b < y.size(); ++b) s += (x[b] - y[b]) * (x[b] - y[b]);
      return std::sqrt(s);
    };
    double sum[4] = {0, 0, 0, 0}, mass = 0.0;
    std::mt19937_64 rng(config.seed);
    std::uniform_int_distribution<size_t> pick(0, kept.size() - 1);
    for (int trial = 0; trial < 4000; ++trial) {
      const index::Signature& a = described[kept[pick(rng)]].raw;
      const index::Signature& b = described[kept[pick(rng)]].raw;
      for (const index::Feature& fa : a.features) {
        for (const index::Feature& fb : b.features) {
          const double w = fa.weight * fb.weight;
          sum[0] += w * std::abs(fa.integral_geodesic - fb.integral_geodesic);
          sum[1] += w * config.ground.k_scale * l2(fa.curvature, fb.curvature);
          sum[2] += w * config.ground.a_scale * l2(fa.area, fb.area);
          sum[3] += w * config.ground.h_scale * l2(fa.distance, fb.distance);
          mass += w;
        }
      }
    }
    std::printf("mean scaled Eq. 7 terms over feature pairs: G %.4f  K %.4f  A %.4f  H %.4f\n",
                sum[0] / mass, sum[1] / mass, sum[2] / mass, sum[3] / mass);
  }
  if (!dump.empty()) {
    std::ofstream out(dump);
    for (int i : kept) {
      const Described& d = described[i];
      out << "model " << models[i].name << " " << models[i].label << " points " << d.points
          << " rings " << d.rings << "\n";
      for (size_t f = 0; f < d.raw.features.size(); ++f) {
        const index::Feature& x = d.raw.features[f];
        out << (static_cast<int>(f) < d.points ? "P" : "R") << " w " << x.weight << " g " << x.integral_geodesic;
        out << "\n  K";
        for (double v : x.curvature) out << " " << v;
        out << "\n  A";
        for (double v : x.area) out << " " << v;
        out << "\n  H";
        for (double v : x.distance) out << " " << v;
        out << "\n";
      }
    }
  }

  // Distance matrices over all models (full, so that timing is honest and
  // the matrix can be reused by tuning).
  const size_t n = models.size();
  Matrix tpr_d(n, std::vector<double>(n, 0.0)), d2_d(n, std::vector<double>(n, 0.0));
  // TPR and D2 matrices are timed separately; each worker sums its own
  // busy time so that per-EMD figures do not depend on the thread count.
  std::vector<double> tpr_busy_ms(kept.size(), 0.0), d2_busy_ms(kept.size(), 0.0);
  const Clock::time_point match_start = Clock::now();
  ParallelFor(kept.size(), threads, [&](size_t a) {
    index::EmdSolver solver;
    const int i = kept[a];
    const Clock::time_point t0 = Clock::now();
    for (size_t b = a + 1; b < kept.size(); ++b) {
      const int j = kept[b];
      tpr_d[i][j] = solver.Distance(described[i].tpr, described[j].tpr);
    }
    tpr_busy_ms[a] = MillisecondsSince(t0);
    const Clock::time_point t1 = Clock::now();
    for (size_t b = a + 1; b < kept.size(); ++b) {
      const int j = kept[b];
      d2_d[i][j] = D2Distance(described[i].d2, described[j].d2);
    }
    d2_busy_ms[a] = MillisecondsSince(t1);
  });
  for (int i : kept) {
    for (int j : kept) {
      if (j < i) {
        tpr_d[i][j] = tpr_d[j][i];
        d2_d[i][j] = d2_d[j][i];
      }
    }
  }
  const double pairs = kept.size() * (kept.size() - 1) / 2.0;
  double tpr_total_ms = 0.0, d2_total_ms = 0.0;
  for (double t : tpr_busy_ms) tpr_total_ms += t;
  for (double t : d2_busy_ms) d2_total_ms += t;
  const double emd_us = 1000 * tpr_total_ms / pairs;
  std::printf("matching: %.0f pairs in %.1f ms wall on %d threads; %.2f us per EMD, %.3f us "
              "per D2 (thread time)\n",
              pairs, MillisecondsSince(match_start), threads, emd_us, 1000 * d2_total_ms / pairs);

  // Invariance check: how far each copy lies from its original, against
  // the typical distance between two models of one class.
  std::string copy_note;
  if (invariance) {
    std::vector<double> copy_d, class_d;
    const size_t nb = base.size();
    for (int i : kept) {
      const size_t orig = static_cast<size_t>(i) % nb;
      if (static_cast<size_t>(i) >= nb && described[orig].ok) copy_d.push_back(tpr_d[i][orig]);
      if (static_cast<size_t>(i) < nb) {
        for (int j : kept) {
          if (static_cast<size_t>(j) < nb && j != i && models[j].label == models[i].label) {
            class_d.push_back(tpr_d[i][j]);
          }
        }
      }
    }
    auto median = [](std::vector<double> v) {
      if (v.empty()) return 0.0;
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      return v[v.size() / 2];
    };
    const double copy_max = copy_d.empty() ? 0.0 : *std::max_element(copy_d.begin(), copy_d.end());
    const double class_median = median(class_d);
    int far_copies = 0;
    for (double d : copy_d) far_copies += d > 0.1 * class_median;
    char buf[400];
    std::snprintf(buf, sizeof(buf),
                  "TPR EMD from a rotated/scaled copy to its original: median %.4g, max %.4g, "
                  "%d of %zu copies beyond a tenth of the median EMD between two models of "
                  "one class (%.4g)",
                  median(copy_d), copy_max, far_copies, copy_d.size(), class_median);
    copy_note = buf;
    std::printf("%s\n", buf);
  }

  // Paper Table 7: k-nearest-neighbour search through the VP-tree index
  // (6.2), every model as a query, one thread.
  struct KnnRow {
    size_t k;
    double emds_per_query, ms_per_query;
  };
  std::vector<KnnRow> knn_rows;
  double index_build_ms = 0.0;
  if (index_timing) {
    index::IndexOptions io;
    io.ground = config.ground;
    io.background_rebuild = false;
    index::SignatureIndex vp(io);
    std::vector<std::pair<std::string, index::Signature>> entries;
    for (int i : kept) entries.push_back({std::to_string(i), described[i].raw});
    const Clock::time_point b0 = Clock::now();
    if (absl::Status st = vp.UpsertBatch(entries); !st.ok()) {
      std::cerr << "index: " << st.message() << "\n";
      return 1;
    }
    vp.Rebuild();
    index_build_ms = MillisecondsSince(b0);
    for (size_t k : {size_t{1}, size_t{5}, size_t{10}, size_t{25}, kept.size()}) {
      int64_t emds = 0;
      const Clock::time_point q0 = Clock::now();
      for (int i : kept) {
        index::SearchStats st;
        vp.Knn(described[i].raw, k, &st);
        emds += st.emd_computations;
      }
      knn_rows.push_back({k, static_cast<double>(emds) / kept.size(),
                          MillisecondsSince(q0) / kept.size()});
    }
    std::printf("VP-tree: built in %.1f ms\n", index_build_ms);
    for (const KnnRow& r : knn_rows) {
      std::printf("  k = %4zu: %8.1f EMDs, %8.2f ms per query\n", r.k, r.emds_per_query,
                  r.ms_per_query);
    }
  }

  std::vector<std::string> labels;
  for (int i : kept) labels.push_back(models[i].label);
  const Scores tpr_scores = Evaluate(labels, QueriesFor(tpr_d, kept));
  const Scores d2_scores = Evaluate(labels, QueriesFor(d2_d, kept));
  PrintTable("TPR (EMD, Eq. 7)", tpr_scores);
  PrintTable("D2 (Osada et al. 2001, L1)", d2_scores);

  std::string tune_json;
  if (tune) {
    // Two folds: models alternate between folds within each class. W1..W4
    // are chosen on one fold by a grid over the simplex (step 0.1) that
    // maximizes mean(NN, FT, ST, DCG); the chosen W is reported on the other
    // fold. No per-query or per-class tuning.
    std::map<std::string, int> seen;
    std::vector<int> fold[2];
    for (int i : kept) fold[seen[models[i].label]++ % 2].push_back(i);
    auto fold_scores = [&](const std::vector<int>& members,
                           const index::GroundDistanceOptions& w) {
      std::vector<index::PreparedSignature> prep(members.size());
      for (size_t a = 0; a < members.size(); ++a) {
        prep[a] = *index::Prepare(described[members[a]].raw, w);
      }
      Matrix d(n, std::vector<double>(n, 0.0));
      ParallelFor(members.size(), threads, [&](size_t a) {
        index::EmdSolver solver;
        for (size_t b = a + 1; b < members.size(); ++b) {
          d[members[a]][members[b]] = d[members[b]][members[a]] =
              solver.Distance(prep[a], prep[b]);
        }
      });
      std::vector<std::string> fold_labels;
      for (int i : members) fold_labels.push_back(models[i].label);
      return Evaluate(fold_labels, QueriesFor(d, members));
    };
    // Every W of the grid is scored on both halves once; each half's best W
    // is reported on the other half (the honest estimate), and the W that
    // is best summed over both halves is the one to make the default.
    std::vector<index::GroundDistanceOptions> grid;
    for (int a = 0; a <= 10; ++a) {
      for (int b = 0; a + b <= 10; ++b) {
        for (int c = 0; a + b + c <= 10; ++c) {
          index::GroundDistanceOptions w = config.ground;
          w.w1 = a / 10.0;
          w.w2 = b / 10.0;
          w.w3 = c / 10.0;
          w.w4 = (10 - a - b - c) / 10.0;
          grid.push_back(w);
        }
      }
    }
    std::vector<Metrics> on_half[2];
    for (int f = 0; f < 2; ++f) {
      for (const auto& w : grid) on_half[f].push_back(fold_scores(fold[f], w).overall);
    }
    tune_json = "[";
    for (int f = 0; f < 2; ++f) {
      size_t best = 0;
      for (size_t g = 0; g < grid.size(); ++g) {
        if (Objective(on_half[f][g]) > Objective(on_half[f][best])) best = g;
      }
      const index::GroundDistanceOptions& best_w = grid[best];
      const Metrics& held_out = on_half[1 - f][best];
      const Scores held_out_default = fold_scores(fold[1 - f], config.ground);
      std::printf("\ntune fold %d: W = (%.1f, %.1f, %.1f, %.1f), objective %.3f on "
                  "the tuning half\n  held-out half: %s\n  held-out half with the "
                  "given W: %s\n",
                  f, best_w.w1, best_w.w2, best_w.w3, best_w.w4, Objective(on_half[f][best]),
                  MetricsJson(held_out).c_str(),
                  MetricsJson(held_out_default.overall).c_str());
      char buf[160];
      std::snprintf(buf, sizeof(buf), "%s{\"w\": [%.1f, %.1f, %.1f, %.1f], \"held_out\": ",
                    f ? ", " : "", best_w.w1, best_w.w2, best_w.w3, best_w.w4);
      tune_json += buf + MetricsJson(held_out) + "}";
    }
    size_t both = 0;
    for (size_t g = 0; g < grid.size(); ++g) {
      if (Objective(on_half[0][g]) + Objective(on_half[1][g]) >
          Objective(on_half[0][both]) + Objective(on_half[1][both])) {
        both = g;
      }
    }
    std::printf("\ntune: best W over both halves (the default to choose): "
                "(%.1f, %.1f, %.1f, %.1f), objectives %.3f / %.3f\n",
                grid[both].w1, grid[both].w2, grid[both].w3, grid[both].w4,
                Objective(on_half[0][both]), Objective(on_half[1][both]));
    tune_json += "]";
  }

  if (!out_dir.empty()) {
    fs::create_directories(out_dir);
    std::string json = "{\"models\": " + std::to_string(kept.size()) +
                       ", \"classes\": " + std::to_string(tpr_scores.per_class.size()) +
                       ", \"tpr\": {\"overall\": " + MetricsJson(tpr_scores.overall) +
                       ", \"per_class\": {";
    bool first = true;
    for (const auto& [cls, m] : tpr_scores.per_class) {
      json += (first ? "" : ", ") + std::string("\"") + cls + "\": " + MetricsJson(m);
      first = false;
    }
    json += "}}, \"d2\": {\"overall\": " + MetricsJson(d2_scores.overall) + "}" +
            (tune_json.empty() ? "" : ", \"tuning\": " + tune_json) + "}\n";
    WriteText(fs::path(out_dir) / "results.json", json);
    {
      // The paper's Tables 5-7 in this run's figures, plus the metric tables.
      const double nk = static_cast<double>(kept.size());
      double features = 0.0;
      for (int i : kept) features += described[i].points + described[i].rings;
      std::string md;
      char buf[512];
      md += MarkdownScores("TPR (EMD, Eq. 7)", tpr_scores);
      md += MarkdownScores("D2 (Osada et al. 2001, L1)", d2_scores);
      md += "#### Features per model (mean)\n\n| class | points | rings |\n|---|---:|---:|\n";
      for (const auto& [cls, pr] : features_per_class) {
        const double c = models_per_class[cls];
        std::snprintf(buf, sizeof(buf), "| %s | %.2f | %.2f |\n", cls.c_str(), pr.first / c,
                      pr.second / c);
        md += buf;
      }
      std::snprintf(buf, sizeof(buf),
                    "\n#### Feature extraction (paper Table 5 form)\n\n| | TPR |\n|---|---:|\n"
                    "| average vertices / faces per model | %.0f / %.0f |\n"
                    "| average topological features per model | %.1f |\n"
                    "| average extraction time per model | %.1f ms |\n",
                    sum_vertices / nk, sum_faces / nk, features / nk, extract_ms / nk);
      md += buf;
      for (const auto& [stage, ms] : stage_ms) {
        std::snprintf(buf, sizeof(buf), "| &nbsp;&nbsp;stage %s | %.1f ms |\n", stage.c_str(),
                      ms / nk);
        md += buf;
      }
      std::snprintf(buf, sizeof(buf),
                    "\n#### Matching (paper Table 6 form)\n\n| | TPR | D2 |\n|---|---:|---:|\n"
                    "| average time for matching one model | %.1f us | %.2f us |\n"
                    "| average time for one query (all %zu others) | %.2f ms | %.3f ms |\n"
                    "| all %zu models as queries (thread time) | %.2f s | %.3f s |\n",
                    emd_us, 1000 * d2_total_ms / pairs, kept.size() - 1,
                    emd_us * (nk - 1) / 1000, d2_total_ms / pairs * (nk - 1), kept.size(),
                    2 * tpr_total_ms / 1000, 2 * d2_total_ms / 1000);
      md += buf;
      if (!knn_rows.empty()) {
        std::snprintf(buf, sizeof(buf),
                      "\n#### k-NN through the VP-tree (paper Table 7 form, one thread)\n\n"
                      "Index build: %.1f ms for %zu models.\n\n| k | EMDs per query | time per "
                      "query |\n|---:|---:|---:|\n",
                      index_build_ms, kept.size());
        md += buf;
        for (const KnnRow& r : knn_rows) {
          std::snprintf(buf, sizeof(buf), "| %zu | %.1f | %.2f ms |\n", r.k, r.emds_per_query,
                        r.ms_per_query);
          md += buf;
        }
      }
      if (!copy_note.empty()) md += "\n" + copy_note + ".\n";
      WriteText(fs::path(out_dir) / "tables.md", md);
    }
    Curve tpr_curve{"TPR", tpr_scores.overall.pr}, d2_curve{"D2", d2_scores.overall.pr};
    WriteText(fs::path(out_dir) / "precision_recall.svg",
              PrecisionRecallSvg({tpr_curve, d2_curve}, "Precision-recall"));
    WriteText(fs::path(out_dir) / "similarity_tpr.svg",
              SimilaritySvg(MeanSimilarity(labels, QueriesFor(tpr_d, kept)),
                            "TPR mean class similarity"));
    WriteText(fs::path(out_dir) / "similarity_d2.svg",
              SimilaritySvg(MeanSimilarity(labels, QueriesFor(d2_d, kept)),
                            "D2 mean class similarity"));
    std::printf("\nwrote %s/{results.json,tables.md,precision_recall.svg,similarity_tpr.svg,similarity_d2.svg}\n",
                out_dir.c_str());
  }
  return 0;
}

}  // namespace
}  // namespace tpr::eval

int main(int argc, char** argv) { return tpr::eval::Run(argc, argv); }
