// `tpr promote`: turns the follower addressed by --indexer into a primary
// (IndexerAdmin.Promote); `tpr promote --status` only reports its role and
// lag (IndexerAdmin.ReplicationStatus). Stop the old primary first, then
// promote, then point the gateway's shard map at the new primary
// (deploy/README.md, "Promotion").
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>

#include "client/cli/cli_util.h"
#include "client/cli/command.h"
#include "common/grpc_status.h"

namespace tpr::cli {
namespace {

int RunStatus(const Globals& g, AdminTarget& admin) {
  grpc::ClientContext context;
  admin.prepare(&context);
  tpr::v1::ReplicationStatusResponse response;
  grpc::Status status = admin.stub->ReplicationStatus(
      &context, tpr::v1::ReplicationStatusRequest(), &response);
  if (!status.ok())
    return Fail("promote --status", tpr::common::FromGrpcStatus(status));
  if (g.json) {
    std::printf("%s\n", ToJson(response).c_str());
  } else if (response.role() == "primary") {
    std::printf("%s: primary at sequence %llu, database %s\n",
                g.indexer.c_str(),
                static_cast<unsigned long long>(response.applied_sequence()),
                response.db_identity().c_str());
  } else {
    std::printf(
        "%s: follower of %s (database %s), applied %llu, primary %llu, %llu "
        "behind, "
        "%s, last heard %lld ms ago\n",
        g.indexer.c_str(), response.primary().c_str(),
        response.db_identity().c_str(),
        static_cast<unsigned long long>(response.applied_sequence()),
        static_cast<unsigned long long>(response.primary_sequence()),
        static_cast<unsigned long long>(response.behind()),
        response.caught_up() ? "caught up" : "catching up",
        static_cast<long long>(response.last_heard_ms()));
    if (!response.error().empty()) {
      std::printf("%s: NOT tailing, the primary refuses: %s\n",
                  g.indexer.c_str(), response.error().c_str());
    }
  }
  return 0;
}

int RunPromote(const Globals& g, bool status_only) {
  std::optional<AdminTarget> admin = ConnectAdmin(g);
  if (!admin) return 2;
  if (status_only) return RunStatus(g, *admin);
  grpc::ClientContext context;
  admin->prepare(&context);
  tpr::v1::PromoteResponse response;
  grpc::Status status =
      admin->stub->Promote(&context, tpr::v1::PromoteRequest(), &response);
  if (!status.ok()) return Fail("promote", tpr::common::FromGrpcStatus(status));
  if (g.json) {
    std::printf("%s\n", ToJson(response).c_str());
  } else if (response.former_primary().empty()) {
    std::printf("%s is a primary already\n", g.indexer.c_str());
  } else {
    std::printf(
        "%s promoted (followed %s up to sequence %llu); it accepts writes "
        "now\n",
        g.indexer.c_str(), response.former_primary().c_str(),
        static_cast<unsigned long long>(response.applied_sequence()));
  }
  return 0;
}

const bool kRegistered = RegisterCommand(
    {"promote",
     "make a follower tpr-indexer a primary, or show its lag (admin)",
     [](CLI::App& sub) {
       auto status_only = std::make_shared<bool>(false);
       sub.add_flag("--status", *status_only,
                    "only report the role and replication lag, change nothing");
       return [status_only](const Globals& g) {
         return RunPromote(g, *status_only);
       };
     },
     "tpr --indexer 127.0.0.1:7012 promote --status"});

}  // namespace
}  // namespace tpr::cli
