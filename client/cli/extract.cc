// `tpr extract MESH...`: the signature summary of meshes, extracted by
// tpr-extractor (points, rings, mesh statistics, stage timings, warnings);
// with --thumbnail and --preview, one mesh's pictures saved to files.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/cli_util.h"
#include "client/cli/command.h"

namespace tpr::cli {
namespace {

struct ExtractFlags {
  std::vector<std::string> meshes;
  // Sent with every mesh; --bands and --handles fill it.
  tpr::v1::ExtractOptions options;
  std::string thumbnail;  // where to save the thumbnail PNG
  std::string preview;    // where to save the preview PLY
  bool no_overlay = false;
};

// Saves the pictures of `r` that the flags ask for; returns the failures.
int SavePictures(const std::string& path, const ExtractFlags& flags,
                 const tpr::v1::ExtractResponse& r) {
  int failures = 0;
  if (!flags.thumbnail.empty()) {
    absl::Status s =
        r.media().thumbnail_png().empty()
            ? absl::InternalError("the extractor returned no thumbnail")
            : WriteBytesToFile(flags.thumbnail, r.media().thumbnail_png());
    if (!s.ok()) failures += Fail(path, s);
  }
  if (!flags.preview.empty()) {
    absl::Status s =
        r.media().preview_ply().empty()
            ? absl::InternalError("the extractor returned no preview")
            : WriteBytesToFile(flags.preview, r.media().preview_ply());
    if (!s.ok()) failures += Fail(path, s);
  }
  return failures;
}

void PrintSummary(const std::string& path, const tpr::v1::ExtractResponse& r) {
  const tpr::v1::Signature& s = r.signature();
  double total = 0;
  std::string stages;
  for (const tpr::v1::StageTiming& t : r.timings()) {
    total += t.milliseconds();
    absl::StrAppend(&stages, stages.empty() ? "" : ", ", t.stage(), " ",
                    absl::StrFormat("%.1f", t.milliseconds()));
  }
  std::printf(
      "%s: %d points, %d rings (%lld vertices, %lld faces, genus %lld); "
      "%.1f ms [%s]\n",
      TextField(path).c_str(), CountKind(s, tpr::v1::FEATURE_KIND_POINT),
      CountKind(s, tpr::v1::FEATURE_KIND_RING),
      static_cast<long long>(s.mesh().vertices()),
      static_cast<long long>(s.mesh().faces()),
      static_cast<long long>(s.mesh().genus()), total, stages.c_str());
  for (const std::string& w : r.warnings()) {
    std::printf("  warning: %s\n", TextField(w).c_str());
  }
}

int RunExtract(const Globals& g, const ExtractFlags& flags) {
  tpr::v1::MediaOptions media;
  media.set_thumbnail(!flags.thumbnail.empty());
  media.set_thumbnail_overlay(!flags.no_overlay);
  media.set_preview(!flags.preview.empty());
  const bool pictures = media.thumbnail() || media.preview();
  if (pictures && flags.meshes.size() != 1) {
    return FailUsage(
        "extract: --thumbnail and --preview take exactly one MESH");
  }
  std::optional<tpr::client::ExtractorClient> client = ConnectExtractor(g);
  if (!client) return 2;
  int failures = 0;
  for (const std::string& path : flags.meshes) {
    absl::StatusOr<tpr::v1::ExtractResponse> r =
        client->ExtractFile(path, flags.options, media);
    if (r.ok() && pictures) {
      failures += SavePictures(path, flags, *r);
      // The pictures are in the files; keep the JSON line short.
      r->clear_media();
    }
    if (!r.ok()) {
      ++failures;
      if (g.json) {
        std::printf("{\"file\":%s,\"error\":%s}\n", JsonString(path).c_str(),
                    JsonString(r.status().ToString()).c_str());
      } else {
        Fail(path, r.status());
      }
    } else if (g.json) {
      std::printf("{\"file\":%s,\"response\":%s}\n", JsonString(path).c_str(),
                  ToJson(*r).c_str());
    } else {
      PrintSummary(path, *r);
    }
  }
  return failures == 0 ? 0 : 1;
}

const bool kRegistered = RegisterCommand(
    {"extract", "print the signature summary of meshes",
     [](CLI::App& sub) {
       auto flags = std::make_shared<ExtractFlags>();
       sub.add_option("MESH", flags->meshes, "mesh files (OFF, OBJ, PLY, STL)")
           ->required();
       sub.add_option_function<int>(
           "--bands",
           [flags](const int& bands) { flags->options.set_bands(bands); },
           "geodesic bands per feature (0: default 20)");
       AddHandlesOption(sub, &flags->options);
       sub.add_option("--thumbnail", flags->thumbnail,
                      "save the mesh's thumbnail (256 x 256 PNG) to FILE");
       sub.add_option("--preview", flags->preview,
                      "save the mesh's preview (binary PLY, at most 5,000 "
                      "triangles) to FILE");
       sub.add_flag("--no-overlay", flags->no_overlay,
                    "thumbnail without the TPR overlay");
       AddTopologyOption(sub, &flags->options);
       return [flags](const Globals& g) { return RunExtract(g, *flags); };
     },
     "tpr extract dog.off --thumbnail dog.png"});

}  // namespace
}  // namespace tpr::cli
