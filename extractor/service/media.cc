#include "extractor/service/media.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "extractor/lib/preview.h"
#include "extractor/lib/thumbnail.h"

namespace tpr::extractor {

bool WantsMedia(const v1::MediaOptions& options) {
  return options.thumbnail() || options.preview();
}

bool NeedsExplanation(const v1::MediaOptions& options) {
  return options.thumbnail() && options.thumbnail_overlay();
}

v1::ModelMedia MakeMedia(const extract::Mesh& mesh,
                         const extract::ExtractResult& result,
                         const v1::MediaOptions& options,
                         std::vector<std::string>* warnings) {
  v1::ModelMedia media;
  if (options.thumbnail()) {
    extract::ThumbnailOverlay overlay;
    if (NeedsExplanation(options) && result.explanation.has_value()) {
      overlay = extract::OverlayFromExplanation(result.signature,
                                                *result.explanation);
    }
    absl::StatusOr<std::string> png =
        extract::RenderThumbnailPng(mesh, overlay, extract::ThumbnailOptions{});
    if (png.ok()) {
      media.set_thumbnail_png(*std::move(png));
    } else {
      warnings->push_back(
          absl::StrCat("no thumbnail: ", png.status().message()));
    }
  }
  if (options.preview()) {
    absl::StatusOr<std::string> ply =
        extract::MakePreviewPly(mesh, extract::PreviewOptions{});
    if (ply.ok()) {
      media.set_preview_ply(*std::move(ply));
    } else {
      warnings->push_back(absl::StrCat("no preview: ", ply.status().message()));
    }
  }
  return media;
}

}  // namespace tpr::extractor
