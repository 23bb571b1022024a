// The TPR pipeline (sections 4 and 5): ExtractSignature runs the stages in
// the paper's order, each a function below over the stage modules, plus the
// per-stage timing, threading and degenerate-mesh policy.
#include "extractor/lib/extract.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/parallel.h"
#include "common/signature_limits.h"
#include "common/status_macros.h"
#include "extractor/lib/critical_points.h"
#include "extractor/lib/features.h"
#include "extractor/lib/mesh_handles.h"
#include "extractor/lib/source_points.h"
#include "extractor/lib/topological_points.h"
#include "extractor/lib/topological_rings.h"

namespace tpr::extract {
namespace {

using Clock = std::chrono::steady_clock;

class StageTimer {
 public:
  explicit StageTimer(std::vector<StageTiming>* timings) : timings_(timings) {}
  void Finish(const char* stage) {
    const Clock::time_point now = Clock::now();
    timings_->push_back(
        {stage,
         std::chrono::duration<double, std::milli>(now - start_).count()});
    start_ = now;
  }

 private:
  std::vector<StageTiming>* timings_;
  Clock::time_point start_ = Clock::now();
};

// ParallelFor runs body(item, solver) for item in [0, count) on up to
// `threads` threads (common/parallel.h), each with its own solver (solvers
// are not thread-safe; the graph is); on one thread, in the caller with
// `caller_solver`. Items write to their own slots, so results do not depend
// on the thread count.
void ParallelFor(const MeshGraph& graph, DijkstraSolver& caller_solver,
                 int count, int threads,
                 const std::function<void(int, DijkstraSolver&)>& body) {
  if (std::min(std::max(threads, 1), count) <= 1) {
    for (int i = 0; i < count; ++i) body(i, caller_solver);
    return;
  }
  common::ParallelForEachWorker(static_cast<size_t>(count), threads, [&] {
    return [&body, solver = std::make_unique<DijkstraSolver>(graph)](size_t i) {
      body(static_cast<int>(i), *solver);
    };
  });
}

absl::Status ValidateOptions(const Options& o) {
  if (!common::BandsInRange(o.bands)) {
    return absl::InvalidArgumentError(
        absl::StrCat("options: bands ", o.bands, " not in [", common::kMinBands,
                     ", ", common::kMaxBands, "]"));
  }
  if (o.cycle_min_vertices < 0) {
    return absl::InvalidArgumentError(
        "options: cycle_min_vertices must be >= 0");
  }
  if (o.cycle_search_hops < o.cycle_min_vertices + 1) {
    return absl::InvalidArgumentError(
        "options: cycle_search_hops must be >= cycle_min_vertices + 1");
  }
  if (!common::RingLengthInRange(o.ring_length_threshold)) {
    return absl::InvalidArgumentError(
        "options: ring_length_threshold not in [0, 1)");
  }
  if (!common::RingLengthInRange(o.ring_min_length)) {
    return absl::InvalidArgumentError("options: ring_min_length not in [0, 1)");
  }
  if (o.topology != TopologyMethod::kPersistence &&
      o.topology != TopologyMethod::kPaper) {
    return absl::InvalidArgumentError("options: unknown topology method");
  }
  if (!common::ProminenceInRange(o.point_min_prominence)) {
    return absl::InvalidArgumentError(
        "options: point_min_prominence not in [0, 1]");
  }
  if (!common::SpectrumEigenvaluesInRange(o.spectrum_eigenvalues)) {
    return absl::InvalidArgumentError(
        absl::StrCat("options: spectrum_eigenvalues ", o.spectrum_eigenvalues,
                     " not in [0, ", common::kMaxSpectrumEigenvalues, "]"));
  }
  if (o.threads < 0 || o.threads > 256) {
    return absl::InvalidArgumentError("options: threads not in [0, 256]");
  }
  return absl::OkStatus();
}

Feature MakeFeature(FeatureKind kind, double g_norm, SurfaceVectors vectors) {
  Feature f;
  f.kind = kind;
  f.integral_geodesic = g_norm;
  f.curvature = std::move(vectors.curvature);
  f.area = std::move(vectors.area);
  f.distance = std::move(vectors.distance);
  return f;
}

// CutHandlesIfAsked returns the cut mesh when Options::cut_handles asks
// for it and `input` (closed, genus > 0) has a handle to cut
// (mesh_handles.h); a failed cut leaves the mesh as it is, with a warning.
std::optional<HandleCut> CutHandlesIfAsked(const Mesh& input,
                                           const MeshStats& stats,
                                           const Options& options,
                                           std::vector<std::string>* warnings) {
  if (!options.cut_handles || stats.genus <= 0 || stats.boundary_edges != 0) {
    return std::nullopt;
  }
  absl::StatusOr<HandleCut> c = CutHandles(input, HandleCutOptions{});
  if (!c.ok()) {
    warnings->push_back(
        absl::StrCat("handles not cut: ", c.status().message()));
    return std::nullopt;
  }
  if (c->handles_cut == 0) return std::nullopt;
  return std::move(*c);
}

// SpectrumStage computes the Laplace-Beltrami spectrum of the whole mesh:
// with threads > 1 on a thread of its own, started at construction beside
// the TPR stages, otherwise in Finish. The destructor waits for the thread,
// so that an early return of the pipeline never leaves it running.
class SpectrumStage {
 public:
  SpectrumStage(const Mesh& mesh, const Options& options)
      : mesh_(mesh), wanted_(options.spectrum_eigenvalues > 0) {
    static_cast<SpectrumSolverOptions&>(options_) = options.spectrum;
    options_.eigenvalues = options.spectrum_eigenvalues;
    options_.allow_fewer = true;  // a small mesh still gets a signature
    if (wanted_ && options.threads > 1) {
      thread_ = std::thread([this] { Compute(); });
    }
  }
  ~SpectrumStage() {
    if (thread_.joinable()) thread_.join();
  }
  SpectrumStage(const SpectrumStage&) = delete;
  SpectrumStage& operator=(const SpectrumStage&) = delete;

  // Finish stores the spectrum in `result` (its timing is its own
  // thread's when it ran beside the other stages), with a warning when the
  // mesh has fewer eigenvalues than asked for. INTERNAL when the
  // eigensolver fails.
  absl::Status Finish(ExtractResult* result) {
    if (!wanted_) return absl::OkStatus();
    if (thread_.joinable()) {
      thread_.join();
    } else {
      Compute();
    }
    TPR_RETURN_IF_ERROR(spectrum_.status());
    if (static_cast<int>(spectrum_->eigenvalues.size()) <
        options_.eigenvalues) {
      result->warnings.push_back(
          absl::StrCat("mesh has ", spectrum_->vertices, " vertices in ",
                       spectrum_->components, " components: the spectrum has ",
                       spectrum_->eigenvalues.size(), " eigenvalues, not ",
                       options_.eigenvalues));
    }
    result->signature.spectrum = std::move(spectrum_->eigenvalues);
    result->timings.push_back({"spectrum", milliseconds_});
    return absl::OkStatus();
  }

 private:
  void Compute() {
    const Clock::time_point start = Clock::now();
    spectrum_ = LaplaceBeltramiSpectrum(mesh_, options_);
    milliseconds_ =
        std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  }

  const Mesh& mesh_;
  const bool wanted_;
  SpectrumOptions options_;
  absl::StatusOr<Spectrum> spectrum_ = Spectrum{};
  double milliseconds_ = 0.0;
  std::thread thread_;  // last: started once every member above exists
};

// AddShapeWarnings says in `warnings` what of the mesh the paper's
// analysis handles poorly (7.4): handles cut or left, boundaries, several
// components.
void AddShapeWarnings(const MeshStats& stats,
                      const std::optional<HandleCut>& cut,
                      const MeshGraph& graph,
                      std::vector<std::string>* warnings) {
  if (cut) {
    std::string lengths;
    for (double l : cut->cycle_lengths) {
      absl::StrAppend(&lengths, lengths.empty() ? "" : ", ",
                      absl::SixDigits(l / std::sqrt(stats.area)));
    }
    warnings->push_back(absl::StrCat(
        "mesh has genus ", stats.genus, "; cut ", cut->handles_cut,
        " handle(s) along the shortest non-separating cycles (length / "
        "sqrt(area): ",
        lengths, ") and capped them: TPR describes genus-0 surfaces (7.4)"));
  }
  if (stats.genus > 0 && (!cut || cut->handles_cut < stats.genus)) {
    warnings->push_back(
        absl::StrCat("mesh has genus ", stats.genus,
                     "; TPR analysis describes genus-0 surfaces poorly (7.4)"));
  }
  if (stats.boundary_edges > 0) {
    warnings->push_back(
        absl::StrCat("mesh has ", stats.boundary_edges,
                     " boundary edges; TPR assumes closed surfaces (7.4)"));
  }
  if (graph.num_components() > 1) {
    warnings->push_back(absl::StrCat(
        "mesh has ", graph.num_components(),
        " connected components; only the largest (by area) is described"));
  }
}

// Surface: what every stage after the graph reads.
struct Surface {
  const MeshGraph& graph;
  const VertexLinks& links;
  // Angle defects per vertex (the curvature bands of 5.3).
  std::vector<double> defects;
  // Area of the described (largest) component.
  double area = 0.0;
};

// Analyses: Critical Point Analysis from each source (4.3).
struct Analyses {
  // far_a, far_b, then the surface centre.
  std::vector<int32_t> sources;
  // One per source, in that order: the centre's is last.
  std::vector<CriticalPoints> sets;
  // MAX g_o: the largest distance from the surface centre (Eq. 1).
  double max_g_o = 0.0;
  // The bands' common extent when Options::bands_per_feature_extent is
  // false (the far sources' distance, a geodesic diameter estimate), else 0.
  double band_extent = 0.0;

  const CriticalPoints& centre() const { return sets.back(); }
};

// AnalyzeSources runs Critical Point Analysis from far_a, far_b and the
// centre (the centre's last: its saddles end ring extraction, 4.6.3, and its
// field gives MAX g_o), then cleans each with persistence under
// TopologyMethod::kPersistence.
absl::StatusOr<Analyses> AnalyzeSources(const Surface& surface,
                                        DijkstraSolver& solver,
                                        const SourcePoints& sources,
                                        const Options& options) {
  const MeshGraph& graph = surface.graph;
  Analyses a;
  a.sources = {sources.far_a, sources.far_b, sources.centre};
  a.sets.resize(a.sources.size());
  std::vector<absl::Status> status(a.sources.size());
  CriticalPointOptions cpa_options;
  cpa_options.cycle_min_vertices = options.cycle_min_vertices;
  cpa_options.search_hops = options.cycle_search_hops;
  ParallelFor(graph, solver, static_cast<int>(a.sources.size()),
              options.threads, [&](int i, DijkstraSolver&) {
                absl::StatusOr<CriticalPoints> cp = AnalyzeCriticalPoints(
                    graph, surface.links, a.sources[i], cpa_options);
                if (cp.ok()) {
                  a.sets[i] = std::move(*cp);
                } else {
                  status[i] = cp.status();
                }
              });
  for (const absl::Status& st : status) TPR_RETURN_IF_ERROR(st);
  if (options.topology == TopologyMethod::kPersistence) {
    const double min_persistence =
        options.point_min_prominence * std::sqrt(surface.area);
    for (CriticalPoints& set : a.sets) {
      set = SimplifyByPersistence(graph, set, min_persistence);
    }
  }
  for (double d : a.centre().distances) {
    if (d != kUnreachable) a.max_g_o = std::max(a.max_g_o, d);
  }
  if (!options.bands_per_feature_extent) {
    const double d = a.sets[0].distances[sources.far_b];
    if (d != kUnreachable) a.band_extent = d;
  }
  return a;
}

// Points: the topological points (4.4) and what the point stages give each.
struct Points {
  std::vector<TopologicalPoint> points;
  // Integral geodesic G(p) (Eq. 1 needs it; 5.1 reuses it).
  std::vector<double> g;
  // Surface vectors (5.3).
  std::vector<SurfaceVectors> vectors;
  // Ring-extraction start times (Eq. 1).
  std::vector<double> start;

  int size() const { return static_cast<int>(points.size()); }
  std::vector<int32_t> vertices() const {
    std::vector<int32_t> v(points.size());
    for (size_t i = 0; i < points.size(); ++i) v[i] = points[i].vertex;
    return v;
  }
};

// DescribePoints fills each point's integral geodesic and surface vectors
// from one field. A point at a source point (far_a and far_b usually are
// tips) takes the distances of that source's Critical Point Analysis: the
// same field, bit for bit, as a sweep from it (both are the unique fixed
// point of the same relaxations; CriticalPointsTest.DistancesEqualAFreshSweep),
// one sweep less each; a point the surface-centre search swept takes the
// field it kept (IntegralGeodesicOptions::field_budget_bytes).
void DescribePoints(const Surface& surface, DijkstraSolver& solver,
                    const SurfaceCentre& surface_centre,
                    const Analyses& analyses, const Options& options,
                    Points* p) {
  const int n = p->size();
  p->g.assign(n, 0.0);
  p->vectors.assign(n, SurfaceVectors{});
  ParallelFor(surface.graph, solver, n, options.threads,
              [&](int i, DijkstraSolver& s) {
                const int32_t vertex = p->points[i].vertex;
                const std::vector<double>* field = nullptr;
                for (size_t j = 0; j < analyses.sources.size(); ++j) {
                  if (analyses.sources[j] == vertex)
                    field = &analyses.sets[j].distances;
                }
                // Else the field the surface-centre search kept for it (the
                // same solver's sweep from the same vertex, bit for bit;
                // IntegralGeodesicTest.KeptFieldsEqualAFreshSweep).
                if (field == nullptr) field = KeptField(surface_centre, vertex);
                if (field == nullptr) field = &s.Run(vertex);
                p->g[i] = IntegralGeodesicOfField(surface.graph, *field);
                p->vectors[i] = ComputeSurfaceVectors(
                    surface.graph, surface.links, *field, surface.defects,
                    options.bands, surface.area, analyses.band_extent);
              });
}

// DropUnstarted keeps in `p` only the points whose wavefront started in
// `rings`; returns whether any was dropped.
bool DropUnstarted(const RingExtraction& rings, Points* p) {
  bool all_started = true;
  for (int i = 0; i < p->size(); ++i) all_started &= rings.fronts[i].started;
  if (all_started) return false;
  Points kept;
  for (int i = 0; i < p->size(); ++i) {
    if (!rings.fronts[i].started) continue;
    kept.points.push_back(p->points[i]);
    kept.g.push_back(p->g[i]);
    kept.start.push_back(p->start[i]);
    kept.vectors.push_back(std::move(p->vectors[i]));
  }
  *p = std::move(kept);
  return true;
}

// ExtractRings runs Topological Ring Extraction (4.6) from the points. A
// point whose wavefront never started (another front swept its vertex
// before its Eq. 1 start time) lies inside another feature's region, bounds
// no region and would get no effective area (5.2), so it carries no mass
// in the EMD (6.1): it is not a protrusion tip (typically a bump of a
// central body, near the surface centre). It is dropped from `p` and the
// extraction runs again without it (the other fronts are unaffected: it
// never swept a vertex).
absl::StatusOr<RingExtraction> ExtractRings(const Surface& surface,
                                            const Analyses& analyses,
                                            const Options& options, Points* p) {
  RingOptions ring_options;
  ring_options.length_threshold =
      options.topology == TopologyMethod::kPaper
          ? options.ring_length_threshold * analyses.max_g_o
          : options.ring_min_length * std::sqrt(surface.area);
  ring_options.stop_at_centre_saddles = options.ring_stop_at_centre_saddles;
  TPR_ASSIGN_OR_RETURN(
      RingExtraction rings,
      ExtractTopologicalRings(surface.graph, p->vertices(), p->start,
                              analyses.centre().saddles, ring_options));
  if (DropUnstarted(rings, p)) {
    TPR_ASSIGN_OR_RETURN(rings, ExtractTopologicalRings(
                                    surface.graph, p->vertices(), p->start,
                                    analyses.centre().saddles, ring_options));
  }
  return rings;
}

// Rings: the ring fronts of an extraction and their descriptions (5.1, 5.3).
struct Rings {
  // Indices into RingExtraction::fronts of the fronts that are rings.
  std::vector<int32_t> fronts;
  // Integral geodesic G'(U) (Eq. 4).
  std::vector<double> g;
  std::vector<SurfaceVectors> vectors;
};

// DescribeRings sweeps once from each ring's vertex set: g_vs for Eq. 4
// and the bands of 5.3.
Rings DescribeRings(const Surface& surface, DijkstraSolver& solver,
                    const RingExtraction& extraction, const Points& p,
                    int32_t centre, double g_min, const Analyses& analyses,
                    const Options& options) {
  Rings r;
  for (int32_t f = 0; f < static_cast<int32_t>(extraction.fronts.size()); ++f) {
    if (extraction.fronts[f].is_ring) r.fronts.push_back(f);
  }
  const int n = static_cast<int>(r.fronts.size());
  r.g.assign(n, 0.0);
  r.vectors.assign(n, SurfaceVectors{});
  const std::vector<int32_t> point_vertices = p.vertices();
  ParallelFor(
      surface.graph, solver, n, options.threads, [&](int k, DijkstraSolver& s) {
        const Front& front = extraction.fronts[r.fronts[k]];
        const std::vector<double>& d = s.Run(front.ring_vertices);
        // Ancestor point w: the originating point farthest from the ring (5.1).
        int w = front.points.front();
        for (int q : front.points) {
          if (d[point_vertices[q]] > d[point_vertices[w]]) w = q;
        }
        const double g_vs_o = d[centre] == kUnreachable ? 0.0 : d[centre];
        const double g_vs_w =
            d[point_vertices[w]] == kUnreachable ? 0.0 : d[point_vertices[w]];
        r.g[k] = RingIntegralGeodesic(g_vs_o, g_vs_w, g_min, p.g[w]);
        r.vectors[k] = ComputeSurfaceVectors(
            surface.graph, surface.links, d, surface.defects, options.bands,
            surface.area, analyses.band_extent);
      });
  return r;
}

// AssembleSignature fills `result`'s features: the points, then the rings,
// weighted by their effective areas (5.2, Eq. 6). With no point (a blob
// none of whose protrusions survived the vote) one point at the surface
// centre carries the whole area, so the signature stays comparable.
void AssembleSignature(const Surface& surface, const RingExtraction& extraction,
                       Points& p, Rings& r, double g_min, double g_max,
                       const Analyses& analyses, const Options& options,
                       ExtractResult* result) {
  Signature& sig = result->signature;
  if (p.size() == 0) {
    result->warnings.push_back(
        "no topological point found; the signature is one point at the surface "
        "centre");
    Feature f = MakeFeature(
        FeatureKind::kPoint, NormalizeIntegralGeodesic(g_min, g_min, g_max),
        ComputeSurfaceVectors(surface.graph, surface.links,
                              analyses.centre().distances, surface.defects,
                              options.bands, surface.area,
                              analyses.band_extent));
    f.weight = 1.0;
    sig.features.push_back(std::move(f));
  } else {
    const std::vector<double> weights =
        EffectiveAreas(surface.graph, extraction, p.size());
    for (int i = 0; i < p.size(); ++i) {
      sig.features.push_back(MakeFeature(
          FeatureKind::kPoint, NormalizeIntegralGeodesic(p.g[i], g_min, g_max),
          std::move(p.vectors[i])));
    }
    for (size_t k = 0; k < r.fronts.size(); ++k) {
      sig.features.push_back(MakeFeature(
          FeatureKind::kRing, NormalizeIntegralGeodesic(r.g[k], g_min, g_max),
          std::move(r.vectors[k])));
    }
    for (size_t i = 0; i < sig.features.size(); ++i)
      sig.features[i].weight = weights[i];
  }
  double weight_sum = 0.0;
  for (const Feature& f : sig.features) weight_sum += f.weight;
  assert(std::abs(weight_sum - 1.0) < 1e-9);
  (void)weight_sum;
}

// Explain returns the explanation of the features (regions per vertex,
// each feature's vertices), in the input's vertex ids when handles were
// cut (HandleCut::origin maps a cut's copies and caps back).
Explanation Explain(const RingExtraction& extraction, const Points& p,
                    const Rings& r, int32_t centre, const Mesh& input,
                    const std::optional<HandleCut>& cut) {
  Explanation e;
  e.vertex_region = extraction.vertex_region;
  if (p.size() == 0) {
    e.feature_vertices.push_back({centre});
  } else {
    for (int32_t v : p.vertices()) e.feature_vertices.push_back({v});
    for (int32_t f : r.fronts)
      e.feature_vertices.push_back(extraction.fronts[f].ring_vertices);
  }
  if (cut) {
    e.vertex_region.resize(input.positions.size());
    for (std::vector<int32_t>& vertices : e.feature_vertices) {
      for (int32_t& v : vertices) v = cut->origin[v];
      std::sort(vertices.begin(), vertices.end());
      vertices.erase(std::unique(vertices.begin(), vertices.end()),
                     vertices.end());
    }
  }
  return e;
}

}  // namespace

absl::StatusOr<ExtractResult> ExtractSignature(const Mesh& input,
                                               const MeshStats& stats,
                                               const Options& options) {
  TPR_RETURN_IF_ERROR(ValidateOptions(options));
  ExtractResult result;
  StageTimer timer(&result.timings);
  // Handles are cut before every stage, the spectrum's included; the cut's
  // time counts in stage "graph".
  const std::optional<HandleCut> cut =
      CutHandlesIfAsked(input, stats, options, &result.warnings);
  const Mesh& mesh = cut ? cut->mesh : input;
  SpectrumStage spectrum(mesh, options);

  // Stage: mesh graph, 1-ring links and angle defects.
  TPR_ASSIGN_OR_RETURN(MeshGraph graph,
                       MeshGraph::Create(mesh, options.geodesic));
  Surface surface{graph, graph.links(), AngleDefects(mesh, graph.links())};
  const int32_t main_component = graph.largest_component();
  surface.area =
      main_component >= 0 ? graph.component_areas()[main_component] : 0.0;
  if (!(surface.area > 0.0)) {
    return absl::InvalidArgumentError("mesh has zero surface area");
  }
  AddShapeWarnings(stats, cut, graph, &result.warnings);
  timer.Finish("graph");

  // Stage: source points (4.5).
  DijkstraSolver solver(graph);
  TPR_ASSIGN_OR_RETURN(
      SourcePoints sources,
      SelectSourcePoints(graph, solver, options.integral_geodesic));
  const double g_min = sources.surface_centre.g_min;
  double g_max = sources.surface_centre.g_max;
  timer.Finish("source_points");

  TPR_ASSIGN_OR_RETURN(const Analyses analyses,
                       AnalyzeSources(surface, solver, sources, options));
  timer.Finish("critical_points");

  Points points;
  points.points = SelectTopologicalPoints(graph, solver, analyses.sets);
  timer.Finish("topological_points");

  DescribePoints(surface, solver, sources.surface_centre, analyses, options,
                 &points);
  // MAX G is an estimate from the centre search; the points are where G
  // peaks (4.1), so they raise it and Eq. 1 stays non-negative.
  for (double g : points.g) g_max = std::max(g_max, g);
  // The kept fields have served; release them before the ring stages.
  std::vector<std::vector<double>>().swap(
      sources.surface_centre.evaluated_fields);
  timer.Finish("point_features");

  points.start = RingStartTimes(points.g, g_min, g_max, analyses.max_g_o);
  TPR_ASSIGN_OR_RETURN(const RingExtraction extraction,
                       ExtractRings(surface, analyses, options, &points));
  timer.Finish("topological_rings");

  Rings rings = DescribeRings(surface, solver, extraction, points,
                              sources.centre, g_min, analyses, options);
  timer.Finish("ring_features");

  result.signature.stats = stats;
  AssembleSignature(surface, extraction, points, rings, g_min, g_max, analyses,
                    options, &result);
  if (options.explain) {
    result.explanation =
        Explain(extraction, points, rings, sources.centre, input, cut);
  }
  timer.Finish("signature");

  // Stage: the spectrum (started above when it runs beside the TPR stages).
  TPR_RETURN_IF_ERROR(spectrum.Finish(&result));
  return result;
}

}  // namespace tpr::extract
