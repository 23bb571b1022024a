// Status propagation helpers shared by every TPR target.
//
// Debian's Abseil 20220623 ships no status macros, so these are ours. They are
// plain statements (no GNU statement expressions) and so portable.
//
//   TPR_RETURN_IF_ERROR(Validate(mesh));
//   TPR_ASSIGN_OR_RETURN(Mesh mesh, LoadMesh(path));
#ifndef TPR_COMMON_STATUS_MACROS_H_
#define TPR_COMMON_STATUS_MACROS_H_

#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

// TPR_RETURN_IF_ERROR evaluates `expr` (an absl::Status) once and returns it
// from the enclosing function when it is not OK.
#define TPR_RETURN_IF_ERROR(expr)              \
  do {                                         \
    ::absl::Status tpr_status_ = (expr);       \
    if (!tpr_status_.ok()) return tpr_status_; \
  } while (false)

#define TPR_STATUS_CONCAT_INNER_(a, b) a##b
#define TPR_STATUS_CONCAT_(a, b) TPR_STATUS_CONCAT_INNER_(a, b)

// TPR_ASSIGN_OR_RETURN evaluates `rexpr` (an absl::StatusOr<T>), returns its
// status when not OK, and otherwise moves the value into `lhs`, which may be
// a declaration (`auto x`) or an existing variable.
#define TPR_ASSIGN_OR_RETURN(lhs, rexpr)                                       \
  TPR_ASSIGN_OR_RETURN_IMPL_(TPR_STATUS_CONCAT_(tpr_statusor_, __LINE__), lhs, \
                             rexpr)

#define TPR_ASSIGN_OR_RETURN_IMPL_(statusor, lhs, rexpr)   \
  auto statusor = (rexpr);                                 \
  if (!statusor.ok()) return std::move(statusor).status(); \
  lhs = std::move(statusor).value()

#endif  // TPR_COMMON_STATUS_MACROS_H_
