#include "client/cli/usage.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "client/cli/cli_util.h"

namespace tpr::cli {
namespace {

size_t EditDistance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diagonal = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1,
                         diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = up;
    }
  }
  return row[b.size()];
}

std::vector<CLI::App*> Subcommands(CLI::App& app) {
  return app.get_subcommands([](CLI::App*) { return true; });
}

CLI::App* FindSubcommand(CLI::App& app, const std::string& name) {
  for (CLI::App* sub : Subcommands(app)) {
    if (sub->get_name() == name) return sub;
  }
  return nullptr;
}

std::vector<std::string> SubcommandNames(CLI::App& app) {
  std::vector<std::string> names;
  for (CLI::App* sub : Subcommands(app)) names.push_back(sub->get_name());
  return names;
}

// The option `name` of `scope` or of a command above it, else nullptr.
const CLI::Option* FindOption(CLI::App* scope, const std::string& name) {
  for (CLI::App* a = scope; a != nullptr; a = a->get_parent()) {
    if (const CLI::Option* o = a->get_option_no_throw(name)) return o;
  }
  return nullptr;
}

bool IsNumber(const char* word) {
  char* end = nullptr;
  std::strtod(word, &end);
  return end != word && *end == '\0';
}

std::string CommandPath(const CLI::App* app) {
  std::string path;
  for (const CLI::App* a = app; a != nullptr && a->get_parent() != nullptr;
       a = a->get_parent()) {
    path = a->get_name() + (path.empty() ? "" : " " + path);
  }
  return path;
}

int UnknownCommand(CLI::App& scope, const std::string& word) {
  const std::string nearest = NearestWord(word, SubcommandNames(scope));
  const std::string where = CommandPath(&scope);
  return UsageError(
      absl::StrCat("unknown command '", where.empty() ? "" : where + " ", word,
                   "'",
                   nearest.empty() ? "" : "; did you mean '" + nearest + "'?"),
      scope);
}

}  // namespace

std::string NearestWord(const std::string& word,
                        const std::vector<std::string>& words) {
  std::string best;
  size_t best_distance = 3;
  for (const std::string& w : words) {
    const size_t d =
        absl::StartsWith(w, word) && !word.empty() ? 1 : EditDistance(word, w);
    if (d < best_distance) {
      best = w;
      best_distance = d;
    }
  }
  return best;
}

bool WantsJson(int argc, const char* const* argv) {
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--") == 0) return false;
    if (std::strcmp(argv[i], "--json") == 0) return true;
  }
  return false;
}

int UsageError(const std::string& message, const CLI::App& app) {
  const std::string where = CommandPath(&app);
  ReportError(message,
              absl::StrCat("see 'tpr ",
                           where.empty() ? "--help" : "help " + where, "'"),
              /*usage=*/true);
  return 2;
}

std::optional<int> CheckUsage(CLI::App& app, int argc,
                              const char* const* argv) {
  CLI::App* scope = &app;
  for (int i = 1; i < argc; ++i) {
    const std::string word = argv[i];
    if (word == "--") return std::nullopt;
    if (word.size() > 1 && word[0] == '-' && !IsNumber(argv[i])) {
      const std::string name = word.substr(0, word.find('='));
      const CLI::Option* option = FindOption(scope, name);
      bool attached = word.find('=') != std::string::npos;
      if (option == nullptr && word[1] != '-' && word.size() > 2) {
        option = FindOption(scope, word.substr(0, 2));  // -j4
        attached = true;
      }
      if (option == nullptr) {
        const std::string where = CommandPath(scope);
        return UsageError(
            absl::StrCat("unknown option ", name,
                         where.empty() ? "" : " for 'tpr " + where + "'"),
            *scope);
      }
      if (!attached && option->get_items_expected_max() > 0) ++i;
      continue;
    }
    if (Subcommands(*scope).empty()) continue;  // a positional argument
    CLI::App* sub = FindSubcommand(*scope, word);
    if (sub == nullptr) {
      // A command with both subcommands and positionals takes the word.
      if (scope != &app && scope->get_option_no_throw(word) == nullptr &&
          !scope
               ->get_options(
                   [](const CLI::Option* o) { return o->get_positional(); })
               .empty()) {
        continue;
      }
      return UnknownCommand(*scope, word);
    }
    if (sub->get_name() == "help") return std::nullopt;  // topics follow
    scope = sub;
  }
  return std::nullopt;
}

int PrintHelp(CLI::App& app, const std::string& topic) {
  if (topic.empty()) {
    // Not app.help(), which shows the chosen subcommand's (here: help's).
    std::printf("%s", app.get_formatter()
                          ->make_help(&app, "tpr", CLI::AppFormatMode::Normal)
                          .c_str());
    return 0;
  }
  CLI::App* sub = FindSubcommand(app, topic);
  if (sub == nullptr) return UnknownCommand(app, topic);
  std::printf("%s", sub->help("tpr").c_str());
  return 0;
}

}  // namespace tpr::cli
