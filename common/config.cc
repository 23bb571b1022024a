#include "common/config.h"

#include <algorithm>
#include <cstdlib>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/json_text.h"

namespace tpr::common {
namespace {

constexpr char kConfigFlag[] = "--config";
constexpr char kPrintFlag[] = "--print-config";

// TOML as CLI11 reads it, minus the keys whose environment variable is set:
// CLI11 2.1 applies the file before the environment and the environment only
// to options still unset, so without this the file would win.
class EnvOverFileToml final : public CLI::ConfigTOML {
 public:
  explicit EnvOverFileToml(std::string prefix) : prefix_(std::move(prefix)) {}

  std::vector<CLI::ConfigItem> from_config(std::istream& input) const override {
    std::vector<CLI::ConfigItem> items = CLI::ConfigTOML::from_config(input);
    if (prefix_.empty()) return items;
    items.erase(std::remove_if(items.begin(), items.end(),
                               [&](const CLI::ConfigItem& item) {
                                 if (!item.parents.empty()) return false;
                                 const char* value = std::getenv(
                                     EnvName(prefix_, item.name).c_str());
                                 return value != nullptr && value[0] != '\0';
                               }),
                items.end());
    return items;
  }

 private:
  std::string prefix_;
};

// A TOML value: numbers and booleans bare, anything else a quoted string
// (JSON string escaping is valid TOML basic-string escaping).
std::string TomlValue(const std::string& value) {
  double number;
  if (value == "true" || value == "false" || absl::SimpleAtod(value, &number))
    return value;
  return JsonString(value);
}

}  // namespace

std::string EnvName(const std::string& prefix, const std::string& long_name) {
  std::string name = absl::AsciiStrToUpper(long_name);
  std::replace(name.begin(), name.end(), '-', '_');
  return prefix + name;
}

ConfigSupport AddConfigSupport(CLI::App& app, const std::string& env_prefix,
                               std::vector<std::string> secrets) {
  ConfigOptions options;
  options.env_prefix = env_prefix;
  options.secrets = std::move(secrets);
  if (!options.env_prefix.empty()) {
    for (CLI::Option* opt : app.get_options()) {
      const std::vector<std::string>& names = opt->get_lnames();
      if (names.empty() || names[0] == "help") continue;
      opt->envname(EnvName(options.env_prefix, names[0]));
    }
  }
  auto print = std::make_shared<bool>(false);
  app.config_formatter(std::make_shared<EnvOverFileToml>(options.env_prefix));
  app.set_config(
      kConfigFlag, "",
      "TOML file of settings, one `flag-name = value` per line (flags and "
      "environment variables take precedence)");
  app.allow_config_extras(CLI::config_extras_mode::error);
  app.add_flag(
      kPrintFlag, *print,
      "print the effective configuration as TOML (secrets masked) and exit");
  return ConfigSupport(&app, std::move(print), std::move(options));
}

std::string ConfigSupport::Effective() const {
  std::string out;
  for (const CLI::Option* opt : app_->get_options()) {
    const std::vector<std::string>& names = opt->get_lnames();
    if (names.empty()) continue;
    const std::string& name = names[0];
    if (name == "help" || name == "config" || name == "print-config") continue;
    std::string value;
    if (opt->get_expected_min() == 0) {  // A flag.
      value = opt->count() > 0
                  ? (opt->as<bool>() ? "true" : "false")
                  : (opt->get_default_str().empty() ? "false"
                                                    : opt->get_default_str());
    } else if (opt->count() > 0) {
      value = absl::StrJoin(opt->reduced_results(), ",");
    } else {
      value = opt->get_default_str();
    }
    const bool secret =
        std::find(options_.secrets.begin(), options_.secrets.end(), name) !=
        options_.secrets.end();
    std::string source = opt->count() > 0 ? "" : "  # default";
    if (value.empty() && opt->count() == 0) {
      absl::StrAppend(&out, "# ", name, " = (not set)\n");
      continue;
    }
    absl::StrAppend(&out, name, " = ", secret ? "\"***\"" : TomlValue(value),
                    source, "\n");
  }
  return out;
}

}  // namespace tpr::common
