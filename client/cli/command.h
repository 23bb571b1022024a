// The subcommands of `tpr`: each lives in its own file (client/cli/<name>.cc)
// and registers itself here at start-up; main.cc adds every registered
// command to the parser and runs the one the user named. A new command is
// one new file:
//
//   const bool kRegistered = RegisterCommand(
//       {"stats", "index counts and sizes", [](CLI::App& sub) {
//          return [](const Globals& g) { return RunStats(g); };  // exit code
//        }, "tpr stats"});
#ifndef TPR_CLIENT_CLI_COMMAND_H_
#define TPR_CLIENT_CLI_COMMAND_H_

#include <functional>
#include <string>
#include <vector>

#include "client/cli/connection.h"

namespace CLI {
class App;
}  // namespace CLI

namespace tpr::cli {

// CommandAction runs a parsed command and returns the process exit code
// (0 success, 1 failure, 2 bad usage).
using CommandAction = std::function<int(const Globals&)>;

// Command describes one subcommand.
struct Command {
  // Name on the command line, e.g. "query".
  std::string name;
  // One-line description for --help.
  std::string help;
  // Adds the command's arguments and flags to `sub` (which already carries
  // `name` and `help`) and returns the action to run when it was chosen.
  // The action reads the values the parser stored; keep them in storage the
  // action owns (e.g. a std::shared_ptr captured by both).
  std::function<CommandAction(CLI::App& sub)> setup;
  // One typical command line, shown under "Example:" in the command's help.
  std::string example;
};

// RegisterCommand adds `command` to the registry and returns true (for use
// in a namespace-scope initializer). Not thread-safe: call only during
// static initialization or before Commands().
bool RegisterCommand(Command command);

// Commands returns every registered command, sorted by name.
std::vector<Command> Commands();

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_COMMAND_H_
