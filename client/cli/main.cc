// tpr: the command-line tool of TPR Search, over the SDK (tpr/client.h).
//
//   tpr add shapes/                    # index a folder (labels from folders)
//   tpr query shapes/biped/pose_0.off -k 5
//   tpr inspect dog.off -o dog_regions.ply
//   tpr eval shapes/ --out results/     # retrieval quality (NN, FT, ST, ...)
//   tpr help add                        # any command's options and example
//
// Each subcommand is one file of this folder that registers itself
// (command.h); the global flags and the connections are in connection.h,
// the checks of the command line before CLI11 parses it in usage.h.
// Human output goes to stdout (progress and diagnostics to stderr); --json
// prints one JSON object per line on stdout, errors included. Exit code 0
// on success, 1 when anything failed, 2 on bad usage.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "client/cli/cli_util.h"
#include "client/cli/command.h"
#include "client/cli/connection.h"
#include "client/cli/usage.h"

namespace {

// The footer of every subcommand's help: its example, and the global flags
// (connection, TLS, API key), which CLI11 lists only in `tpr --help`.
std::string Footer(const CLI::App& app, const std::string& example) {
  std::string globals;
  for (const CLI::Option* option : app.get_options()) {
    const std::string name = option->get_name();  // "" when hidden
    if (name.empty() || name == "--help" || name == "--version") continue;
    if (!globals.empty()) globals += ", ";
    globals += name;
    if (!option->get_envname().empty())
      globals += " (" + option->get_envname() + ")";
  }
  return "\nExample:\n  " + example +
         "\n\nGlobal options, before or after the command (details: tpr "
         "--help):\n  " +
         globals + "\n";
}

}  // namespace

int main(int argc, char** argv) {
  tpr::cli::Globals g;
  CLI::App app{
      "tpr: TPR Search command-line tool (deformable 3D model retrieval)",
      "tpr"};
  app.require_subcommand(0, 1);
  app.fallthrough();
  app.set_version_flag("--version", std::string("tpr ") + TPR_VERSION_STRING,
                       "print the version and exit");
  tpr::cli::AddGlobalFlags(&app, &g);
  app.footer(
      "\nExamples:\n  tpr add library/\n  tpr query dog.off -k 5\n  tpr "
      "help query\n\nExit codes: 0 success, 1 something failed, 2 bad usage.");

  std::vector<std::pair<CLI::App*, tpr::cli::CommandAction>> actions;
  for (const tpr::cli::Command& command : tpr::cli::Commands()) {
    CLI::App* sub = app.add_subcommand(command.name, command.help);
    actions.emplace_back(sub, command.setup(*sub));
    sub->footer(Footer(app, command.example));
  }
  std::string help_topic;
  CLI::App* help = app.add_subcommand("help", "show a command's help");
  help->add_option("COMMAND", help_topic, "the command, e.g. add");
  help->footer(Footer(app, "tpr help query"));

  tpr::cli::SetJsonErrors(tpr::cli::WantsJson(argc, argv));
  if (std::optional<int> code = tpr::cli::CheckUsage(app, argc, argv))
    return *code;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Help and --version exit 0; every usage error (bad or missing value)
    // exits 2, as documented.
    if (e.get_exit_code() == 0) return app.exit(e);
    return tpr::cli::UsageError(e.what(), app);
  }
  if (*help) return tpr::cli::PrintHelp(app, help_topic);
  for (const auto& [sub, action] : actions) {
    if (*sub) return action(g);
  }
  std::fprintf(stderr, "%s", app.help().c_str());
  return 2;
}
