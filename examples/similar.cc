// similar MESH: the 5 indexed models nearest to a mesh file, over the SDK.
#include <cstdio>

#include "tpr/client.h"

int main(int argc, char** argv) {
  if (argc != 2) return std::fprintf(stderr, "usage: similar MESH\n"), 2;
  auto extractor = tpr::client::ExtractorClient::Connect("127.0.0.1:7001");
  auto indexer = tpr::client::IndexerClient::Connect("127.0.0.1:7002");
  if (!extractor.ok() || !indexer.ok()) return 2;
  auto r = extractor->ExtractFile(argv[1]);
  if (!r.ok())
    return std::fprintf(stderr, "%s\n", r.status().ToString().c_str()), 1;
  tpr::v1::SearchRequest q;
  *q.mutable_signature() = r->signature();
  q.set_k(5);
  auto stream = indexer->Search(q);
  for (tpr::v1::Neighbor n; stream->Next(&n);)
    std::printf("%d %s %.4f\n", n.rank(), n.id().c_str(), n.distance());
  absl::Status done = stream->Finish();
  if (!done.ok())
    return std::fprintf(stderr, "%s\n", done.ToString().c_str()), 1;
}
