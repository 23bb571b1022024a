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
  // Add a file whose content (sha256 of its bytes, stored as the model's
  // metadata "sha256") is already indexed under another id, or appears
  // earlier in the same run. Default true; `tpr add` skips such files with
  // a warning unless --allow-duplicates.
  bool allow_duplicates = true;
};

// AddOutcome is what happened to one item.
struct AddOutcome {
  enum Kind { kAdded, kUpdated, kSkipped, kFailed };
  Kind kind = kFailed;
  std::string error;  // why, for kFailed (the status as text)
  // Why, for kSkipped: "already present", or "same content as ID".
  std::string reason;
};

// AddItems extracts and upserts every item (model id = item.id, label =
// item.label, metadata file_name = the file's base name and sha256 = the
// hex SHA-256 of its bytes) on options.jobs threads, and returns one
// outcome per item, in the items' order. One listing of the index says
// which ids and contents exist: without options.update, ids present are
// skipped, as are ids that someone else adds meanwhile (ALREADY_EXISTS);
// without options.allow_duplicates, so is a file whose content is indexed
// under another id. A file that cannot be read or extracted, or a refused
// upsert, is kFailed with its reason; the other items go on. `progress`, if
// not null, gets one Step per item.
// Errors: the listing's, and a call failing in a way every later call
// would (UNAVAILABLE, UNIMPLEMENTED, UNAUTHENTICATED, PERMISSION_DENIED):
// then no further item is tried and that status is returned, saying how
// many items were done. Cost: one read of each file, one extract and one
// upsert call per item not skipped. Thread-safe (the clients are).
absl::StatusOr<std::vector<AddOutcome>> AddItems(
    const tpr::client::ExtractorClient& extractor,
    const tpr::client::IndexerClient& indexer, const std::vector<Item>& items,
    const AddOptions& options, const tpr::client::CallOptions& call,
    Progress* progress);

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_ADD_H_
