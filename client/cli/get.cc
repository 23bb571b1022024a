// `tpr get ID...`: stored models with their signature summary and metadata;
// `tpr get ID --thumbnail out.png --preview out.ply` also saves its media.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "absl/time/time.h"
#include "client/cli/cli_util.h"
#include "client/cli/command.h"

namespace tpr::cli {
namespace {

void PrintModel(const tpr::v1::Model& m) {
  const tpr::v1::Signature& s = m.signature();
  const absl::Time added = absl::FromUnixMicros(m.added_unix_micros());
  std::printf(
      "id:       %s\nlabel:    %s\nadded:    %s\nfeatures: %d points, %d "
      "rings (%d bands)\nmesh:     %lld vertices, %lld faces, genus %lld, "
      "%lld components\nversion:  %s\n",
      TextField(m.id()).c_str(), TextField(m.label()).c_str(),
      absl::FormatTime("%Y-%m-%d %H:%M:%S UTC", added, absl::UTCTimeZone())
          .c_str(),
      CountKind(s, tpr::v1::FEATURE_KIND_POINT),
      CountKind(s, tpr::v1::FEATURE_KIND_RING), s.options().bands(),
      static_cast<long long>(s.mesh().vertices()),
      static_cast<long long>(s.mesh().faces()),
      static_cast<long long>(s.mesh().genus()),
      static_cast<long long>(s.mesh().components()),
      TextField(s.extractor_version()).c_str());
  std::printf("media:    %s\n", m.media_stored()
                                    ? "thumbnail and preview stored"
                                    : "none (`tpr add --update` makes them)");
  for (const auto& [key, value] : m.metadata()) {
    std::printf("meta:     %s = %s\n", TextField(key).c_str(),
                TextField(value).c_str());
  }
}

struct GetFlags {
  std::vector<std::string> ids;
  std::string thumbnail;  // where to save the thumbnail PNG
  std::string preview;    // where to save the preview PLY
};

// Saves the one model's media the flags ask for; returns the failures.
int SaveMedia(const tpr::client::IndexerClient& indexer,
              const GetFlags& flags) {
  const std::string& id = flags.ids.front();
  int failures = 0;
  if (!flags.thumbnail.empty()) {
    absl::StatusOr<std::string> png = indexer.GetThumbnail(id);
    absl::Status s =
        png.ok() ? WriteBytesToFile(flags.thumbnail, *png) : png.status();
    if (!s.ok()) failures += Fail(id, s);
  }
  if (!flags.preview.empty()) {
    absl::StatusOr<std::string> ply = indexer.GetPreview(id);
    absl::Status s =
        ply.ok() ? WriteBytesToFile(flags.preview, *ply) : ply.status();
    if (!s.ok()) failures += Fail(id, s);
  }
  return failures;
}

int RunGet(const Globals& g, const GetFlags& flags) {
  const bool media = !flags.thumbnail.empty() || !flags.preview.empty();
  if (media && flags.ids.size() != 1) {
    return FailUsage("get: --thumbnail and --preview take exactly one ID");
  }
  std::optional<tpr::client::IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 2;
  int failures = 0;
  for (const std::string& id : flags.ids) {
    absl::StatusOr<tpr::v1::Model> m = indexer->Get(id);
    if (!m.ok()) {
      ++failures;
      Fail(id, m.status());
    } else if (g.json) {
      std::printf("%s\n", ToJson(*m).c_str());
    } else {
      PrintModel(*m);
    }
  }
  if (media && failures == 0) failures += SaveMedia(*indexer, flags);
  return failures == 0 ? 0 : 1;
}

const bool kRegistered = RegisterCommand(
    {"get", "show stored models (and save one's thumbnail and preview)",
     [](CLI::App& sub) {
       auto flags = std::make_shared<GetFlags>();
       sub.add_option("ID", flags->ids, "model ids")->required();
       sub.add_option("--thumbnail", flags->thumbnail,
                      "save the model's thumbnail (256 x 256 PNG) to FILE");
       sub.add_option("--preview", flags->preview,
                      "save the model's preview mesh (binary PLY, at most "
                      "5,000 triangles) to FILE");
       return [flags](const Globals& g) { return RunGet(g, *flags); };
     },
     "tpr get dog1/T305.obj --thumbnail dog.png"});

}  // namespace
}  // namespace tpr::cli
