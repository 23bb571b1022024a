// The one mapping between library statuses (absl::Status) and gRPC statuses.
//
// Abseil's canonical codes are gRPC's codes with the same numbers, so the
// mapping is the identity on code and message; this header exists so that
// every service and the client SDK convert in exactly one place.
//
//   grpc::Status s =
//       tpr::common::ToGrpcStatus(LoadMeshFromBuffer(...).status());
//   absl::Status a = tpr::common::FromGrpcStatus(stub->Extract(&ctx, ...));
//   if (absl::IsInvalidArgument(a)) { ... }
//
// Header-only. Library code never includes this (it would pull in gRPC).
#ifndef TPR_COMMON_GRPC_STATUS_H_
#define TPR_COMMON_GRPC_STATUS_H_

#include <grpcpp/support/status.h>

#include <string>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"

namespace tpr::common {

// ToGrpcStatus returns the gRPC status with the same canonical code and
// message as `status`. OK maps to grpc::Status::OK. Codes outside the
// canonical range (never produced by our libraries) become UNKNOWN. Cost O(len
// of message). Thread-safe.
inline grpc::Status ToGrpcStatus(const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  const int code = static_cast<int>(status.code());
  // absl and gRPC share the numbering 0..16 (both follow google.rpc.Code).
  const grpc::StatusCode grpc_code = (code > 0 && code <= 16)
                                         ? static_cast<grpc::StatusCode>(code)
                                         : grpc::StatusCode::UNKNOWN;
  return grpc::Status(grpc_code, std::string(status.message()));
}

// FromGrpcStatus returns the absl::Status with the same canonical code and
// message as `status` (OkStatus for OK). The inverse of ToGrpcStatus. Cost
// O(len of message). Thread-safe.
inline absl::Status FromGrpcStatus(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  const int code = static_cast<int>(status.error_code());
  const absl::StatusCode absl_code = (code > 0 && code <= 16)
                                         ? static_cast<absl::StatusCode>(code)
                                         : absl::StatusCode::kUnknown;
  return absl::Status(absl_code, absl::string_view(status.error_message()));
}

}  // namespace tpr::common

#endif  // TPR_COMMON_GRPC_STATUS_H_
