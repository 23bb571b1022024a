// Conversions between the extractor library's types (tpr::extract) and the
// wire contract (tpr.v1). The service and the CLI use them; nothing else
// converts, so the two forms cannot drift apart.
//
//   absl::StatusOr<extract::Options> o = OptionsFromProto(request.options());
//   v1::Signature wire = SignatureToProto(result.signature, *o);
//   extract::MeshFormat f = FormatFromProto(request.format());
#ifndef TPR_EXTRACTOR_SERVICE_CONVERT_H_
#define TPR_EXTRACTOR_SERVICE_CONVERT_H_

#include "absl/status/statusor.h"
#include "common/signature_limits.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/lib/signature.h"
#include "tpr/v1/extractor.pb.h"
#include "tpr/v1/signature.pb.h"

namespace tpr::extractor {

// kExtractorVersion is the semantic version stamped into every signature
// (Signature.extractor_version): the project version from CMake.
extern const char kExtractorVersion[];

// kSignatureVersion is stamped into every signature
// (Signature.signature_version); common/signature_limits.h defines it.
using common::kSignatureVersion;

// OptionsFromProto returns the library options for `proto`, a zero field
// meaning the default documented in extractor/lib/extract.h.
// Errors (limits from common/signature_limits.h): INVALID_ARGUMENT when
// bands is outside 1..256, cycle_min_vertices not below the library's
// cycle_search_hops,
// spectrum_eigenvalues outside 0..1000, point_min_prominence outside [0, 1],
// handles or topology not a value this build knows,
// ring_length_threshold or ring_min_length outside [0, 1) or another field
// is negative (the
// message names the field). `max_threads` caps the requested
// Dijkstra threads (a client must not be able to take the whole machine).
// O(1). Thread-safe.
absl::StatusOr<extract::Options> OptionsFromProto(
    const v1::ExtractOptions& proto, int max_threads);

// OptionsToProto returns `options` in wire form, every field filled.
v1::ExtractOptions OptionsToProto(const extract::Options& options);

// FormatFromProto maps the wire format hint to intake's; UNSPECIFIED (and
// any unknown value) becomes kUnknown, which makes intake guess.
extract::MeshFormat FormatFromProto(v1::MeshFormat format);

// StatsToProto returns `stats` in wire form.
v1::MeshStats StatsToProto(const extract::MeshStats& stats);

// SignatureToProto returns the wire signature of `signature` (features,
// spectrum), with its mesh statistics, kExtractorVersion, kSignatureVersion
// and `options` (defaults filled). O(features x
// bands). Thread-safe.
v1::Signature SignatureToProto(const extract::Signature& signature,
                               const extract::Options& options);

// ExplanationToProto returns `explanation` in wire form, each feature's
// vertices with their positions in `mesh` (the mesh the explanation's ids
// refer to: intake's; an id out of range gets no position, which cannot
// happen for an explanation of `mesh`). O(vertices listed). Thread-safe.
v1::Explanation ExplanationToProto(const extract::Explanation& explanation,
                                   const extract::Mesh& mesh);

}  // namespace tpr::extractor

#endif  // TPR_EXTRACTOR_SERVICE_CONVERT_H_
