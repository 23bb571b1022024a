// The TPR pipeline (sections 4 and 5): a short facade over the stage
// modules, plus the per-stage timing, threading and degenerate-mesh policy.
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
  if (o.bands < 1 || o.bands > 1000) {
    return absl::InvalidArgumentError(
        absl::StrCat("options: bands ", o.bands, " not in [1, 1000]"));
  }
  if (o.cycle_min_vertices < 0) {
    return absl::InvalidArgumentError(
        "options: cycle_min_vertices must be >= 0");
  }
  if (o.cycle_search_hops < o.cycle_min_vertices + 1) {
    return absl::InvalidArgumentError(
        "options: cycle_search_hops must be >= cycle_min_vertices + 1");
  }
  if (!(o.ring_length_threshold >= 0.0 && o.ring_length_threshold <= 1.0)) {
    return absl::InvalidArgumentError(
        "options: ring_length_threshold not in [0, 1]");
  }
  if (!(o.ring_min_length >= 0.0 && o.ring_min_length <= 1.0)) {
    return absl::InvalidArgumentError("options: ring_min_length not in [0, 1]");
  }
  if (o.topology != TopologyMethod::kPersistence &&
      o.topology != TopologyMethod::kPaper) {
    return absl::InvalidArgumentError("options: unknown topology method");
  }
  if (!(o.point_min_prominence >= 0.0 && o.point_min_prominence <= 1.0)) {
    return absl::InvalidArgumentError(
        "options: point_min_prominence not in [0, 1]");
  }
  if (o.spectrum_eigenvalues < 0 || o.spectrum_eigenvalues > 1000) {
    return absl::InvalidArgumentError(
        absl::StrCat("options: spectrum_eigenvalues ", o.spectrum_eigenvalues,
                     " not in [0, 1000]"));
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

}  // namespace

absl::StatusOr<ExtractResult> ExtractSignature(const Mesh& input,
                                               const MeshStats& stats,
                                               const Options& options) {
  TPR_RETURN_IF_ERROR(ValidateOptions(options));
  ExtractResult result;
  StageTimer timer(&result.timings);

  // Handles (Options::cut_handles, mesh_handles.h): a closed mesh of genus
  // > 0 is cut to genus 0 before every stage, the spectrum's included. Its
  // time counts in stage "graph".
  std::optional<HandleCut> cut;
  if (options.cut_handles && stats.genus > 0 && stats.boundary_edges == 0) {
    absl::StatusOr<HandleCut> c = CutHandles(input, HandleCutOptions{});
    if (!c.ok()) {
      result.warnings.push_back(
          absl::StrCat("handles not cut: ", c.status().message()));
    } else if (c->handles_cut > 0) {
      cut = std::move(*c);
    }
  }
  const Mesh& mesh = cut ? cut->mesh : input;

  // The Laplace-Beltrami spectrum of the whole mesh needs only
  // the mesh: with threads > 1 it runs on its own thread beside the TPR
  // stages below, otherwise after them. Everything the thread touches is
  // declared before its joiner, which waits for it on every return.
  SpectrumOptions spectrum_options = options.spectrum;
  spectrum_options.eigenvalues = options.spectrum_eigenvalues;
  spectrum_options.allow_fewer = true;  // a small mesh still gets a signature
  absl::StatusOr<Spectrum> spectrum = Spectrum{};
  double spectrum_ms = 0.0;
  const auto compute_spectrum = [&] {
    const Clock::time_point start = Clock::now();
    spectrum = LaplaceBeltramiSpectrum(mesh, spectrum_options);
    spectrum_ms =
        std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  };
  const bool spectrum_wanted = options.spectrum_eigenvalues > 0;
  const bool spectrum_beside = spectrum_wanted && options.threads > 1;
  struct Joiner {
    std::thread thread;
    ~Joiner() {
      if (thread.joinable()) thread.join();
    }
  } spectrum_thread;
  if (spectrum_beside) spectrum_thread.thread = std::thread(compute_spectrum);

  // Stage: mesh graph, 1-ring links and angle defects.
  TPR_ASSIGN_OR_RETURN(MeshGraph graph,
                       MeshGraph::Create(mesh, options.geodesic));
  const VertexLinks& links = graph.links();  // built with the graph
  const std::vector<double> defects = AngleDefects(mesh, links);
  const int32_t main_component = graph.largest_component();
  const double area =
      main_component >= 0 ? graph.component_areas()[main_component] : 0.0;
  if (!(area > 0.0)) {
    return absl::InvalidArgumentError("mesh has zero surface area");
  }
  if (cut) {
    std::string lengths;
    for (double l : cut->cycle_lengths) {
      absl::StrAppend(&lengths, lengths.empty() ? "" : ", ",
                      absl::SixDigits(l / std::sqrt(stats.area)));
    }
    result.warnings.push_back(absl::StrCat(
        "mesh has genus ", stats.genus, "; cut ", cut->handles_cut,
        " handle(s) along the shortest non-separating cycles (length / "
        "sqrt(area): ",
        lengths, ") and capped them: TPR describes genus-0 surfaces (7.4)"));
  }
  if (stats.genus > 0 && (!cut || cut->handles_cut < stats.genus)) {
    result.warnings.push_back(
        absl::StrCat("mesh has genus ", stats.genus,
                     "; TPR analysis describes genus-0 surfaces poorly (7.4)"));
  }
  if (stats.boundary_edges > 0) {
    result.warnings.push_back(
        absl::StrCat("mesh has ", stats.boundary_edges,
                     " boundary edges; TPR assumes closed surfaces (7.4)"));
  }
  if (graph.num_components() > 1) {
    result.warnings.push_back(absl::StrCat(
        "mesh has ", graph.num_components(),
        " connected components; only the largest (by area) is described"));
  }
  timer.Finish("graph");

  // Stage: source points (4.5).
  DijkstraSolver solver(graph);
  TPR_ASSIGN_OR_RETURN(
      SourcePoints sources,
      SelectSourcePoints(graph, solver, options.integral_geodesic));
  const int32_t centre = sources.centre;
  const double g_min = sources.surface_centre.g_min;
  double g_max = sources.surface_centre.g_max;
  timer.Finish("source_points");

  // Stage: Critical Point Analysis from each source (4.3). The centre's
  // analysis is last: its saddles end ring extraction (4.6.3) and its field
  // gives MAX g_o (Eq. 1).
  const std::vector<int32_t> source_list = {sources.far_a, sources.far_b,
                                            centre};
  std::vector<CriticalPoints> sets(source_list.size());
  std::vector<absl::Status> cpa_status(source_list.size());
  CriticalPointOptions cpa_options;
  cpa_options.cycle_min_vertices = options.cycle_min_vertices;
  cpa_options.search_hops = options.cycle_search_hops;
  ParallelFor(graph, solver, static_cast<int>(source_list.size()),
              options.threads, [&](int i, DijkstraSolver&) {
                absl::StatusOr<CriticalPoints> cp = AnalyzeCriticalPoints(
                    graph, links, source_list[i], cpa_options);
                if (cp.ok()) {
                  sets[i] = std::move(*cp);
                } else {
                  cpa_status[i] = cp.status();
                }
              });
  for (const absl::Status& s : cpa_status) TPR_RETURN_IF_ERROR(s);
  if (options.topology == TopologyMethod::kPersistence) {
    const double min_persistence =
        options.point_min_prominence * std::sqrt(area);
    for (CriticalPoints& set : sets) {
      set = SimplifyByPersistence(graph, set, min_persistence);
    }
  }
  const CriticalPoints& centre_set = sets.back();
  double max_g_o = 0.0;
  for (double d : centre_set.distances) {
    if (d != kUnreachable) max_g_o = std::max(max_g_o, d);
  }
  // Geodesic diameter estimate: the far source points' distance (4.5), for
  // bands of one absolute extent (Options::bands_per_feature_extent false).
  double band_extent = 0.0;
  if (!options.bands_per_feature_extent) {
    const double d = sets[0].distances[sources.far_b];
    if (d != kUnreachable) band_extent = d;
  }
  timer.Finish("critical_points");

  // Stage: Topological Point Selection (4.4).
  std::vector<TopologicalPoint> points =
      SelectTopologicalPoints(graph, solver, sets);
  int num_points = static_cast<int>(points.size());
  timer.Finish("topological_points");

  // Stage: integral geodesic at each point (Eq. 1 needs it; 5.1 reuses it)
  // and, from the same sweep, the point's surface vectors (5.3). A point at
  // a source point (far_a and far_b usually are tips) takes the distances
  // of that source's Critical Point Analysis: the same field, bit for bit,
  // as a sweep from it (both are the unique fixed point of the same
  // relaxations; CriticalPointsTest.DistancesEqualAFreshSweep), one sweep
  // less each; a point the surface-centre search swept takes the field it
  // kept (IntegralGeodesicOptions::field_budget_bytes).
  std::vector<double> point_g(num_points, 0.0);
  std::vector<SurfaceVectors> point_vectors(num_points);
  ParallelFor(graph, solver, num_points, options.threads,
              [&](int i, DijkstraSolver& s) {
                const std::vector<double>* field = nullptr;
                for (size_t j = 0; j < source_list.size(); ++j) {
                  if (source_list[j] == points[i].vertex) {
                    field = &sets[j].distances;
                  }
                }
                // Else the field the surface-centre search kept for it (the
                // same solver's sweep from the same vertex, bit for bit;
                // IntegralGeodesicTest.KeptFieldsEqualAFreshSweep).
                if (field == nullptr) {
                  field = KeptField(sources.surface_centre, points[i].vertex);
                }
                if (field == nullptr) field = &s.Run(points[i].vertex);
                point_g[i] = IntegralGeodesicOfField(graph, *field);
                point_vectors[i] =
                    ComputeSurfaceVectors(graph, links, *field, defects,
                                          options.bands, area, band_extent);
              });
  // MAX G is an estimate from the centre search; the points are where G
  // peaks (4.1), so they raise it and Eq. 1 stays non-negative.
  for (double g : point_g) g_max = std::max(g_max, g);
  // The kept fields have served; release them before the ring stages.
  std::vector<std::vector<double>>().swap(
      sources.surface_centre.evaluated_fields);
  timer.Finish("point_features");

  // Stage: Topological Ring Extraction (4.6).
  RingOptions ring_options;
  ring_options.length_threshold =
      options.topology == TopologyMethod::kPaper
          ? options.ring_length_threshold * max_g_o
          : options.ring_min_length * std::sqrt(area);
  ring_options.stop_at_centre_saddles = options.ring_stop_at_centre_saddles;
  std::vector<int32_t> point_vertices(num_points);
  for (int i = 0; i < num_points; ++i) point_vertices[i] = points[i].vertex;
  std::vector<double> start = RingStartTimes(point_g, g_min, g_max, max_g_o);
  TPR_ASSIGN_OR_RETURN(
      RingExtraction rings,
      ExtractTopologicalRings(graph, point_vertices, start, centre_set.saddles,
                              ring_options));
  // A point whose wavefront never started (another front swept its vertex
  // before its Eq. 1 start time) lies inside another feature's region, bounds
  // no region and would get no effective area (5.2), so it carries no mass
  // in the EMD (6.1): it is not a protrusion tip (typically a bump of a
  // central body, near the surface centre). Drop it and run again without
  // it (the other fronts are unaffected: it never swept a vertex).
  std::vector<int> kept;
  for (int i = 0; i < num_points; ++i) {
    if (rings.fronts[i].started) kept.push_back(i);
  }
  if (static_cast<int>(kept.size()) < num_points) {
    std::vector<TopologicalPoint> kept_points;
    std::vector<double> kept_g, kept_start;
    std::vector<SurfaceVectors> kept_vectors;
    for (int i : kept) {
      kept_points.push_back(points[i]);
      kept_g.push_back(point_g[i]);
      kept_start.push_back(start[i]);
      kept_vectors.push_back(std::move(point_vectors[i]));
    }
    points = std::move(kept_points);
    point_g = std::move(kept_g);
    start = std::move(kept_start);
    point_vectors = std::move(kept_vectors);
    num_points = static_cast<int>(points.size());
    point_vertices.resize(num_points);
    for (int i = 0; i < num_points; ++i) point_vertices[i] = points[i].vertex;
    TPR_ASSIGN_OR_RETURN(
        rings, ExtractTopologicalRings(graph, point_vertices, start,
                                       centre_set.saddles, ring_options));
  }
  std::vector<int32_t> ring_fronts;
  for (int32_t f = 0; f < static_cast<int32_t>(rings.fronts.size()); ++f) {
    if (rings.fronts[f].is_ring) ring_fronts.push_back(f);
  }
  const int num_rings = static_cast<int>(ring_fronts.size());
  timer.Finish("topological_rings");

  // Stage: ring features. One vertex-set sweep per ring gives g_vs for
  // Eq. 4 and the bands of 5.3.
  std::vector<double> ring_g(num_rings, 0.0);
  std::vector<SurfaceVectors> ring_vectors(num_rings);
  ParallelFor(
      graph, solver, num_rings, options.threads, [&](int k, DijkstraSolver& s) {
        const Front& front = rings.fronts[ring_fronts[k]];
        const std::vector<double>& d = s.Run(front.ring_vertices);
        // Ancestor point w: the originating point farthest from the ring (5.1).
        int w = front.points.front();
        for (int p : front.points) {
          if (d[point_vertices[p]] > d[point_vertices[w]]) w = p;
        }
        const double g_vs_o = d[centre] == kUnreachable ? 0.0 : d[centre];
        const double g_vs_w =
            d[point_vertices[w]] == kUnreachable ? 0.0 : d[point_vertices[w]];
        ring_g[k] = RingIntegralGeodesic(g_vs_o, g_vs_w, g_min, point_g[w]);
        ring_vectors[k] = ComputeSurfaceVectors(
            graph, links, d, defects, options.bands, area, band_extent);
      });
  timer.Finish("ring_features");

  // Stage: effective areas (5.2) and the signature.
  Signature& sig = result.signature;
  sig.stats = stats;
  if (num_points == 0) {
    // No protrusion survived the vote (a blob): one point at the surface
    // centre carries the whole area, so the signature stays comparable.
    result.warnings.push_back(
        "no topological point found; the signature is one point at the surface "
        "centre");
    Feature f = MakeFeature(
        FeatureKind::kPoint, NormalizeIntegralGeodesic(g_min, g_min, g_max),
        ComputeSurfaceVectors(graph, links, centre_set.distances, defects,
                              options.bands, area, band_extent));
    f.weight = 1.0;
    sig.features.push_back(std::move(f));
  } else {
    const std::vector<double> weights =
        EffectiveAreas(graph, rings, num_points);
    for (int i = 0; i < num_points; ++i) {
      sig.features.push_back(
          MakeFeature(FeatureKind::kPoint,
                      NormalizeIntegralGeodesic(point_g[i], g_min, g_max),
                      std::move(point_vectors[i])));
    }
    for (int k = 0; k < num_rings; ++k) {
      sig.features.push_back(
          MakeFeature(FeatureKind::kRing,
                      NormalizeIntegralGeodesic(ring_g[k], g_min, g_max),
                      std::move(ring_vectors[k])));
    }
    for (size_t i = 0; i < sig.features.size(); ++i)
      sig.features[i].weight = weights[i];
  }
  double weight_sum = 0.0;
  for (const Feature& f : sig.features) weight_sum += f.weight;
  assert(std::abs(weight_sum - 1.0) < 1e-9);
  (void)weight_sum;

  if (options.explain) {
    Explanation e;
    e.vertex_region = rings.vertex_region;
    if (num_points == 0) {
      e.feature_vertices.push_back({centre});
    } else {
      for (int i = 0; i < num_points; ++i)
        e.feature_vertices.push_back({point_vertices[i]});
      for (int32_t f : ring_fronts)
        e.feature_vertices.push_back(rings.fronts[f].ring_vertices);
    }
    if (cut) {
      // Back to the input's ids: a cut's copies and caps map to the
      // vertices they come from (HandleCut::origin).
      e.vertex_region.resize(input.positions.size());
      for (std::vector<int32_t>& vertices : e.feature_vertices) {
        for (int32_t& v : vertices) v = cut->origin[v];
        std::sort(vertices.begin(), vertices.end());
        vertices.erase(std::unique(vertices.begin(), vertices.end()),
                       vertices.end());
      }
    }
    result.explanation = std::move(e);
  }
  timer.Finish("signature");

  // Stage: the spectrum (started above when it runs beside the TPR stages;
  // its timing is then its own thread's).
  if (spectrum_wanted) {
    if (spectrum_beside) {
      spectrum_thread.thread.join();
    } else {
      compute_spectrum();
    }
    TPR_RETURN_IF_ERROR(spectrum.status());
    if (static_cast<int>(spectrum->eigenvalues.size()) <
        options.spectrum_eigenvalues) {
      result.warnings.push_back(
          absl::StrCat("mesh has ", spectrum->vertices, " vertices in ",
                       spectrum->components, " components: the spectrum has ",
                       spectrum->eigenvalues.size(), " eigenvalues, not ",
                       options.spectrum_eigenvalues));
    }
    sig.spectrum = std::move(spectrum->eigenvalues);
    result.timings.push_back({"spectrum", spectrum_ms});
  }
  return result;
}

}  // namespace tpr::extract
