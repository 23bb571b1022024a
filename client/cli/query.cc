// `tpr query`: the k nearest models to a mesh (extracted on the fly) or to a
// stored id, printed as each neighbour arrives.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

#include "client/cli/cli_util.h"
#include "client/cli/command.h"

namespace tpr::cli {
namespace {

struct QueryFlags {
  std::string mesh;
  std::string id;
  std::string label;
  int k = 10;
  double radius = 0;
  bool exclude_self = false;
  // --rank-by: "" or "default" (the intent's weighting), "paper" (the EMD
  // of Eq. 7 alone) or "spectrum" (the spectrum alone; both
  // SearchRequest.ranking). Every one is searched with the VP-tree.
  std::string rank_by;
  // --intent (SearchRequest.intent; --rank-by paper|spectrum overrides it).
  tpr::v1::Intent intent = tpr::v1::INTENT_UNSPECIFIED;
  // Extraction of MESH (--handles).
  tpr::v1::ExtractOptions extract;
};

int RunQuery(const Globals& g, const QueryFlags& flags) {
  if (flags.mesh.empty() == flags.id.empty()) {
    return FailUsage("query: give either MESH or --id ID");
  }
  std::optional<tpr::client::IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 2;
  tpr::v1::SearchRequest request;
  if (!flags.mesh.empty()) {
    std::optional<tpr::client::ExtractorClient> extractor = ConnectExtractor(g);
    if (!extractor) return 2;
    absl::StatusOr<tpr::v1::ExtractResponse> r =
        extractor->ExtractFile(flags.mesh, flags.extract);
    if (!r.ok()) return Fail(flags.mesh, r.status());
    *request.mutable_signature() = std::move(*r->mutable_signature());
  } else {
    request.set_id(flags.id);
    request.set_exclude_self(flags.exclude_self);
  }
  request.set_k(flags.k);
  request.set_radius(flags.radius);
  request.set_label(flags.label);
  request.set_intent(flags.intent);
  if (std::optional<tpr::v1::Ranking> ranking = NamedRanking(flags.rank_by)) {
    *request.mutable_ranking() = *std::move(ranking);
  }
  std::unique_ptr<tpr::client::SearchStream> stream = indexer->Search(request);
  bool header = false;
  for (tpr::v1::Neighbor n; stream->Next(&n);) {
    if (g.json) {
      std::printf("{\"rank\":%d,\"id\":%s,\"label\":%s,\"distance\":%s}\n",
                  n.rank(), JsonString(n.id()).c_str(),
                  JsonString(n.label()).c_str(),
                  JsonNumber(n.distance()).c_str());
    } else {
      if (!header) {
        std::printf("%4s  %-40s %-20s %s\n", "rank", "id", "label", "distance");
      }
      header = true;
      std::printf("%4d  %-40s %-20s %.6f\n", n.rank(),
                  TextField(n.id()).c_str(), TextField(n.label()).c_str(),
                  n.distance());
    }
    std::fflush(stdout);  // show each neighbour as it arrives
  }
  absl::Status status = stream->Finish();
  if (!status.ok()) return Fail("query", status);
  if (!g.json && stream->Stats() != nullptr) {
    const tpr::v1::SearchStats& s = *stream->Stats();
    std::fprintf(stderr,
                 "(%lld EMDs, %lld lower bounds, %lld nodes, %.2f ms on the "
                 "server)\n",
                 static_cast<long long>(s.emd_computations()),
                 static_cast<long long>(s.lower_bounds()),
                 static_cast<long long>(s.nodes_visited()), s.milliseconds());
  }
  return 0;
}

const bool kRegistered = RegisterCommand(
    {"query", "k nearest models to a mesh or a stored id",
     [](CLI::App& sub) {
       auto flags = std::make_shared<QueryFlags>();
       sub.add_option("MESH", flags->mesh, "query mesh file");
       sub.add_option("--id", flags->id,
                      "query by stored model id instead of a mesh");
       sub.add_option("-k", flags->k, "number of neighbours")
           ->capture_default_str()
           ->check(CLI::Range(1, 1000000));
       sub.add_option("--radius", flags->radius,
                      "only neighbours at distance <= radius (0: any); 0 is "
                      "the same shape, the scale depends on --intent "
                      "(docs/distances.md)")
           ->check(CLI::NonNegativeNumber);
       sub.add_option("--label", flags->label, "only models with this label");
       sub.add_flag("--exclude-self", flags->exclude_self,
                    "with --id, leave the query model out");
       sub.add_option("--rank-by", flags->rank_by,
                      "default: the intent's distance; paper: the distance "
                      "of Tam and Lau's paper alone (the EMD between the "
                      "topological points); spectrum: the shape spectrum "
                      "alone (both override --intent)")
           ->check(
               CLI::IsMember({"default", "paper", "spectrum"}).description(""))
           ->type_name("default|paper|spectrum");
       AddIntentOption(sub, &flags->intent);
       AddHandlesOption(sub, &flags->extract);
       AddTopologyOption(sub, &flags->extract);
       return [flags](const Globals& g) { return RunQuery(g, *flags); };
     },
     "tpr query dog.off -k 5            # or: tpr query --id dog1/T305.obj"});

}  // namespace
}  // namespace tpr::cli
