// `tpr add`, and the indexing it shares with `tpr eval`: each mesh file is
// extracted by tpr-extractor and its signature stored in tpr-indexer under
// the item's id and label, several at once.
//
//   AddOptions options;  options.jobs = 4;
//   absl::StatusOr<std::vector<AddOutcome>> out =
//       AddItems(extractor, indexer, items, options, call, &progress);
#ifndef TPR_CLIENT_CLI_ADD_H_
#define TPR_CLIENT_CLI_ADD_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "client/cli/cli_util.h"
#include "client/cli/connection.h"
#include "eval/lib/dataset.h"
#include "tpr/client.h"

namespace tpr::cli {

using tpr::eval::Item;

// AddOptions: how AddItems works.
struct AddOptions {
  // Uploads in flight at once. Default 4.
  int jobs = 4;
  // Replace ids already present (re-extract and overwrite). Default false:
  // ids present are skipped, so that re-runs are cheap and safe.
  bool update = false;
  // Extraction options sent with every mesh (ExtractOptions; zero fields:
  // the extractor's defaults). Default: all defaults.
  tpr::v1::ExtractOptions extract;
  // Pictures asked of the extractor with every mesh and stored with its
  // model (Model.media). Default: none; `tpr add` asks for the thumbnail
  // with the TPR overlay and the preview (--no-media, --no-overlay).
  tpr::v1::MediaOptions media;
};

// AddOutcome is what happened to one item.
struct AddOutcome {
  enum Kind { kAdded, kUpdated, kSkipped, kFailed };
  Kind kind = kFailed;
  std::string error;  // why, for kFailed (the status as text)
};

// AddItems extracts and upserts every item (model id = item.id, label =
// item.label, metadata file_name = the file's base name) on options.jobs
// threads, and returns one outcome per item, in the items' order. Without
// options.update, one listing of the index says which ids exist; those are
// skipped, as are ids that someone else adds meanwhile (ALREADY_EXISTS).
// A file that cannot be read or extracted, or a refused upsert, is kFailed
// with its reason; the other items go on. `progress`, if not null, gets one
// Step per item.
// Errors: only the listing's (e.g. UNAVAILABLE); per-item failures are
// outcomes. Cost: one extract and one upsert call per item not skipped.
// Thread-safe (the clients are).
absl::StatusOr<std::vector<AddOutcome>> AddItems(
    const tpr::client::ExtractorClient& extractor,
    const tpr::client::IndexerClient& indexer, const std::vector<Item>& items,
    const AddOptions& options, const tpr::client::CallOptions& call,
    Progress* progress);

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_ADD_H_
