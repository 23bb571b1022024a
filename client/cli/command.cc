#include "client/cli/command.h"

#include <algorithm>
#include <utility>

namespace tpr::cli {
namespace {

// A function-local static, so that registration from other translation
// units' initializers never sees it before it is constructed.
std::vector<Command>& Registry() {
  static auto* registry = new std::vector<Command>();
  return *registry;
}

}  // namespace

bool RegisterCommand(Command command) {
  Registry().push_back(std::move(command));
  return true;
}

std::vector<Command> Commands() {
  std::vector<Command> all = Registry();
  std::sort(all.begin(), all.end(),
            [](const Command& a, const Command& b) { return a.name < b.name; });
  return all;
}

}  // namespace tpr::cli
