// `tpr key new --role ROLE --keys FILE [--name NAME]`: make an API key,
// append its hash and role to the servers' keys file (common/auth.h), and
// print the key once. The file is created with mode 0600 when missing; an
// existing file must parse (the new line is not appended to a broken file).
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "absl/strings/str_cat.h"
#include "client/cli/cli_util.h"
#include "client/cli/command.h"
#include "common/auth.h"

namespace tpr::cli {
namespace {

struct KeyArgs {
  std::string role = "read";
  std::string keys_file;
  std::string name;
};

int RunKeyNew(const Globals& g, const KeyArgs& args) {
  absl::StatusOr<common::Role> role = common::ParseRole(args.role);
  if (!role.ok()) return Fail("--role", role.status());
  std::string existing;
  {
    std::ifstream in(args.keys_file, std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    existing = text.str();
  }
  if (absl::StatusOr<common::KeyTable> table = common::ParseKeyFile(existing);
      !table.ok()) {
    return Fail(args.keys_file, table.status());
  }
  absl::StatusOr<std::string> key = common::NewApiKey();
  if (!key.ok()) return Fail("key new", key.status());
  std::string line = common::KeyFileLine(*key, *role, args.name) + "\n";
  if (!existing.empty() && existing.back() != '\n') line = "\n" + line;
  const int fd = open(args.keys_file.c_str(),
                      O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0600);
  if (fd < 0 ||
      write(fd, line.data(), line.size()) !=
          static_cast<ssize_t>(line.size()) ||
      fsync(fd) != 0) {
    if (fd >= 0) close(fd);
    return Fail(args.keys_file,
                absl::UnavailableError("cannot append to the keys file"));
  }
  close(fd);
  if (g.json) {
    std::printf("{\"key\":%s,\"role\":%s,\"hash\":%s}\n",
                JsonString(*key).c_str(),
                JsonString(common::RoleName(*role)).c_str(),
                JsonString(common::HashApiKey(*key)).c_str());
  } else {
    std::printf("%s\n", key->c_str());
    std::fprintf(stderr,
                 "tpr: added a %s key to %s; it is shown only now (the file "
                 "keeps its hash). "
                 "Servers pick it up within a second or on SIGHUP.\n",
                 std::string(common::RoleName(*role)).c_str(),
                 args.keys_file.c_str());
  }
  return 0;
}

const bool kRegistered = RegisterCommand(
    {"key", "API keys: `tpr key new --role ROLE --keys FILE`",
     [](CLI::App& sub) {
       auto args = std::make_shared<KeyArgs>();
       sub.require_subcommand(1);
       CLI::App* make = sub.add_subcommand(
           "new", "make a key, append its hash to FILE, print it once");
       make->add_option("--role", args->role, "read, write or admin")
           ->capture_default_str()
           ->check(CLI::IsMember({"read", "write", "admin"}));
       make->add_option("--keys", args->keys_file,
                        "the servers' --api-keys file")
           ->required();
       make->add_option("--name", args->name,
                        "a label kept next to the hash (no spaces)");
       return [args](const Globals& g) { return RunKeyNew(g, *args); };
     },
     "tpr key new --role write --keys /etc/tpr/keys.txt --name ingest"});

}  // namespace
}  // namespace tpr::cli
