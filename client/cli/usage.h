// The command line of `tpr` checked before CLI11 parses it, so that a
// mistake gets the message that names it: an unknown command (with the
// nearest one: `tpr ad` -> "did you mean 'add'?"), an unknown option (even
// when a required argument is missing too: `tpr add --hepl`), and `tpr help
// COMMAND`. Every usage error exits 2.
//
//   SetJsonErrors(WantsJson(argc, argv));
//   if (std::optional<int> code = CheckUsage(app, argc, argv)) return *code;
#ifndef TPR_CLIENT_CLI_USAGE_H_
#define TPR_CLIENT_CLI_USAGE_H_

#include <optional>
#include <string>
#include <vector>

namespace CLI {
class App;
}  // namespace CLI

namespace tpr::cli {

// WantsJson returns whether --json is among the arguments (before "--").
bool WantsJson(int argc, const char* const* argv);

// CheckUsage walks the arguments against `app`'s commands and options and
// returns 2, having printed why, for the first unknown command or option;
// nullopt when every word is known (values are left to CLI11).
std::optional<int> CheckUsage(CLI::App& app, int argc, const char* const* argv);

// UsageError prints "tpr: MESSAGE" and a pointer to the help on stderr (a
// JSON object on stdout under --json) and returns 2.
int UsageError(const std::string& message, const CLI::App& app);

// PrintHelp prints the help of command `topic` ("" for `tpr` itself) on
// stdout and returns 0, or a usage error for an unknown command.
int PrintHelp(CLI::App& app, const std::string& topic);

// NearestWord returns the word of `words` closest to `word` (a prefix of
// it, or at most two edits away), or "" when none is. Pure.
std::string NearestWord(const std::string& word,
                        const std::vector<std::string>& words);

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_USAGE_H_
