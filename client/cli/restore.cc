// `tpr restore --from DIR --into DATA_DIR [--backup-id N]`: restores a
// backup (IndexerAdmin.Restore) into an empty directory on the machine of
// the tpr-indexer addressed by --indexer; start a tpr-indexer on DATA_DIR
// afterwards. A non-empty DATA_DIR is refused (FAILED_PRECONDITION).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>

#include "client/cli/cli_util.h"
#include "client/cli/command.h"
#include "common/grpc_status.h"

namespace tpr::cli {
namespace {

struct RestoreArgs {
  std::string from;
  std::string into;
  uint32_t backup_id = 0;
};

int RunRestore(const Globals& g, const RestoreArgs& args) {
  std::optional<AdminTarget> admin = ConnectAdmin(g);
  if (!admin) return 2;
  grpc::ClientContext context;
  admin->prepare(&context);
  tpr::v1::RestoreRequest request;
  request.set_backup_dir(args.from);
  request.set_backup_id(args.backup_id);
  request.set_data_dir(args.into);
  tpr::v1::RestoreResponse response;
  grpc::Status status = admin->stub->Restore(&context, request, &response);
  if (!status.ok()) return Fail("restore", tpr::common::FromGrpcStatus(status));
  if (g.json) {
    std::printf("%s\n", ToJson(response).c_str());
    return 0;
  }
  std::printf(
      "restored backup %u (%lld models) into %s; start it with "
      "tpr-indexer --data-dir %s\n",
      response.backup_id(), static_cast<long long>(response.models()),
      args.into.c_str(), args.into.c_str());
  return 0;
}

const bool kRegistered = RegisterCommand(
    {"restore", "restore a backup into an empty data directory (admin)",
     [](CLI::App& sub) {
       auto args = std::make_shared<RestoreArgs>();
       sub.add_option("--from", args->from,
                      "backup set directory (tpr backup --to)")
           ->required();
       sub.add_option("--into", args->into,
                      "empty or absent data directory on the indexer's machine")
           ->required();
       sub.add_option("--backup-id", args->backup_id,
                      "backup to restore (0: the latest)");
       return [args](const Globals& g) { return RunRestore(g, *args); };
     },
     "tpr restore --from /backups/tpr --into /var/lib/tpr/indexer"});

}  // namespace
}  // namespace tpr::cli
