// `tpr backup --to DIR`: an online, incremental, verified backup of one
// tpr-indexer (IndexerAdmin.Backup). DIR is on the indexer's machine. Behind
// a gateway, back up each shard's primary (or a caught-up follower) in turn.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>

#include "client/cli/cli_util.h"
#include "client/cli/command.h"
#include "common/grpc_status.h"

namespace tpr::cli {
namespace {

struct BackupArgs {
  std::string dir;
  int keep_last = 0;
};

int RunBackup(const Globals& g, const BackupArgs& args) {
  std::optional<AdminTarget> admin = ConnectAdmin(g);
  if (!admin) return 2;
  grpc::ClientContext context;
  admin->prepare(&context);
  tpr::v1::BackupRequest request;
  request.set_backup_dir(args.dir);
  request.set_keep_last(args.keep_last);
  tpr::v1::BackupResponse response;
  grpc::Status status = admin->stub->Backup(&context, request, &response);
  if (!status.ok()) return Fail("backup", tpr::common::FromGrpcStatus(status));
  if (g.json) {
    std::printf("%s\n", ToJson(response).c_str());
    return 0;
  }
  std::printf(
      "backup %u of %s in %s: %lld models, %u files, %.1f MiB (%.1f MiB "
      "copied), "
      "verified\n",
      response.backup_id(), g.indexer.c_str(), args.dir.c_str(),
      static_cast<long long>(response.models()), response.files(),
      response.size_bytes() / 1048576.0, response.copied_bytes() / 1048576.0);
  return 0;
}

const bool kRegistered = RegisterCommand(
    {"backup", "online incremental verified backup of one tpr-indexer (admin)",
     [](CLI::App& sub) {
       auto args = std::make_shared<BackupArgs>();
       sub.add_option("--to", args->dir,
                      "backup set directory on the indexer's machine (created "
                      "if missing)")
           ->required();
       sub.add_option("--keep-last", args->keep_last,
                      "afterwards keep only this many newest backups (0: all)")
           ->check(CLI::NonNegativeNumber);
       return [args](const Globals& g) { return RunBackup(g, *args); };
     },
     "tpr --indexer 127.0.0.1:7002 backup --to /backups/tpr --keep-last 7"});

}  // namespace
}  // namespace tpr::cli
