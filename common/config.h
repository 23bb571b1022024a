// Configuration of the TPR commands: every flag of a CLI11 app can also be
// set in a TOML file (--config FILE.toml) and by an environment variable
// named <PREFIX><FLAG>, upper case with '-' as '_' (--max-k of tpr-indexer
// is TPR_INDEXER_MAX_K).
//
// Precedence: a flag on the command line beats the environment, which beats
// the file, which beats the built-in default. (CLI11 2.1 alone would let the
// file beat the environment; the file's keys set in the environment are
// dropped before CLI11 applies them.)
//
//   CLI::App app{"tpr-indexer"};
//   app.add_option("--listen", listen);  ...every option...
//   tpr::common::ConfigSupport config =
//       tpr::common::AddConfigSupport(app, "TPR_INDEXER_");
//   CLI11_PARSE(app, argc, argv);
//   if (config.print_requested()) {
//     std::cout << config.Effective();
//     return 0;
//   }
//
// A key of the file that names no flag is an error (CLI11 reports it and
// the command exits 2), so a misspelt setting never passes silently.
#ifndef TPR_COMMON_CONFIG_H_
#define TPR_COMMON_CONFIG_H_

#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

namespace tpr::common {

// ConfigOptions: how AddConfigSupport extends an app.
struct ConfigOptions {
  // Prefix of the environment variables, e.g. "TPR_INDEXER_". Empty: no
  // environment variables. Default empty.
  std::string env_prefix;
  // Long names (without "--") whose values --print-config masks as "***",
  // e.g. {"api-key"}. Default none.
  std::vector<std::string> secrets;
};

// ConfigSupport: the state AddConfigSupport leaves behind; query it after
// parsing. Cheap to copy; refers to the app, which must outlive it.
class ConfigSupport {
 public:
  ConfigSupport(const CLI::App* app, std::shared_ptr<bool> print,
                ConfigOptions options)
      : app_(app), print_(std::move(print)), options_(std::move(options)) {}

  // print_requested is true when --print-config was given.
  bool print_requested() const { return *print_; }

  // Effective returns the effective configuration as TOML, one
  // `name = value` line per option (every option, defaults included;
  // secrets as "***"), readable again by --config. Call after parsing.
  std::string Effective() const;

 private:
  const CLI::App* app_;
  std::shared_ptr<bool> print_;
  ConfigOptions options_;
};

// EnvName returns the environment variable of the option `long_name`
// ("max-k") under `prefix` ("TPR_INDEXER_"): "TPR_INDEXER_MAX_K".
std::string EnvName(const std::string& prefix, const std::string& long_name);

// AddConfigSupport adds --config FILE and --print-config to `app` and gives
// every option added so far (call it after the last add_option) its
// environment variable <env_prefix><NAME> (none when env_prefix is empty);
// --print-config masks the options named in `secrets`. Thread-compatible
// (call once, before parsing).
ConfigSupport AddConfigSupport(CLI::App& app, const std::string& env_prefix,
                               std::vector<std::string> secrets = {});

}  // namespace tpr::common

#endif  // TPR_COMMON_CONFIG_H_
