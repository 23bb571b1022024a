// The pictures tpr-extractor returns beside a signature (ExtractResponse.
// media): the thumbnail (extractor/lib/thumbnail.h) and the preview mesh
// (extractor/lib/preview.h), made from the mesh as intake read it.
//
//   std::vector<std::string> warnings;
//   v1::ModelMedia media = MakeMedia(loaded.mesh, &result, request.media(),
//                                    &warnings);
#ifndef TPR_EXTRACTOR_SERVICE_MEDIA_H_
#define TPR_EXTRACTOR_SERVICE_MEDIA_H_

#include <string>
#include <vector>

#include "extractor/lib/mesh.h"
#include "extractor/lib/signature.h"
#include "tpr/v1/extractor.pb.h"
#include "tpr/v1/signature.pb.h"

namespace tpr::extractor {

// WantsMedia returns whether `options` asks for any picture.
bool WantsMedia(const v1::MediaOptions& options);

// NeedsExplanation returns whether `options` needs the extraction's
// explanation (the thumbnail's overlay draws the features' vertices).
bool NeedsExplanation(const v1::MediaOptions& options);

// MakeMedia returns what `options` asks for: the thumbnail (256 x 256 PNG,
// with the TPR overlay from `result`'s explanation when
// options.thumbnail_overlay; the explanation must then be set) and the
// preview PLY (at most 5,000 triangles). A picture that cannot be made
// (a preview whose decimation cannot reach the limit) is left empty and a
// sentence saying why is appended to `warnings`: pictures never fail an
// extraction. Deterministic. Cost: see docs/benchmarks.md (BM_Media).
// Thread-safe.
v1::ModelMedia MakeMedia(const extract::Mesh& mesh,
                         const extract::ExtractResult& result,
                         const v1::MediaOptions& options,
                         std::vector<std::string>* warnings);

}  // namespace tpr::extractor

#endif  // TPR_EXTRACTOR_SERVICE_MEDIA_H_
