// tpr: the command-line tool of TPR Search, over the SDK (tpr/client.h).
//
//   tpr add shapes/                    # index a folder (labels from folders)
//   tpr query shapes/biped/pose_0.off -k 5
//   tpr inspect dog.off -o dog_regions.ply
//   tpr eval shapes/ --out results/     # retrieval quality (NN, FT, ST, ...)
//
// Each subcommand is one file of this folder that registers itself
// (command.h); the global flags and the connections are in connection.h.
// Human output goes to stdout (progress and diagnostics to stderr); --json
// prints one JSON object per line. Exit code 0 on success, 1 when anything
// failed, 2 on bad usage.
#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "client/cli/command.h"
#include "client/cli/connection.h"

int main(int argc, char** argv) {
  tpr::cli::Globals g;
  CLI::App app{
      "tpr: TPR Search command-line tool (deformable 3D model retrieval)"};
  app.require_subcommand(1);
  app.fallthrough();
  tpr::cli::AddGlobalFlags(&app, &g);

  // Each subcommand's --help names the global flags (connection, TLS, API
  // key), which CLI11 lists only in `tpr --help`.
  std::string globals;
  for (const CLI::Option* option : app.get_options()) {
    const std::string name =
        option->get_name();  // the long name; "" when hidden
    if (name.empty() || name == "--help") continue;
    if (!globals.empty()) globals += ", ";
    globals += name;
    if (!option->get_envname().empty())
      globals += " (" + option->get_envname() + ")";
  }
  const std::string footer =
      "\nGlobal options, before or after the subcommand (details: tpr "
      "--help):\n  " +
      globals;
  std::vector<std::pair<CLI::App*, tpr::cli::CommandAction>> actions;
  for (const tpr::cli::Command& command : tpr::cli::Commands()) {
    CLI::App* sub = app.add_subcommand(command.name, command.help);
    sub->footer(footer);
    actions.emplace_back(sub, command.setup(*sub));
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // CLI11 prints the message (or the help, which exits 0); every usage
    // error (unknown flag, bad or missing value) exits 2, as documented.
    return app.exit(e) == 0 ? 0 : 2;
  }
  for (const auto& [sub, action] : actions) {
    if (*sub) return action(g);
  }
  return 2;
}
